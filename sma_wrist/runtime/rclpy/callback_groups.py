"""Callback groups; the single-threaded virtual-time executor never runs callbacks
concurrently, so groups only record membership."""

from __future__ import annotations

from typing import Any


class CallbackGroup:
    def __init__(self) -> None:
        self.entities: list[Any] = []

    def add_entity(self, entity: Any) -> None:
        self.entities.append(entity)

    def has_entity(self, entity: Any) -> bool:
        return entity in self.entities

    def can_execute(self, entity: Any) -> bool:
        return True

    def beginning_execution(self, entity: Any) -> bool:
        return True

    def ending_execution(self, entity: Any) -> None:
        pass


class MutuallyExclusiveCallbackGroup(CallbackGroup):
    pass


class ReentrantCallbackGroup(CallbackGroup):
    pass
