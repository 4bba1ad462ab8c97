"""The interface contract (``msg_defs/topics.yaml``) as typed data.

One source of truth: nodes take topic names, types and QoS from here, the docs table and
the tests read the same file. No ROS imports: message classes are resolved by the caller
(``std_msgs.msg.Float64`` under either runtime).

The file is found by :func:`sma_wrist.share.share_path` under every install layout.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from sma_wrist.core.errors import SmaWristError
from sma_wrist.share import ShareFileNotFound, share_path


class ContractError(SmaWristError):
    """The contract file is missing or inconsistent, or a topic is not in it."""


@dataclass(frozen=True)
class Topic:
    name: str
    type: str  # e.g. 'std_msgs/msg/Float64'
    unit: str
    rate_hz: float  # nominal, 0 = event driven
    publisher: str
    subscribers: tuple[str, ...]
    description: str
    qos: str = 'reliable'  # 'reliable' (depth: ``depth``) or 'transient_local' (latched, depth 1)
    alt_publisher: str | None = None
    #: KEEP_LAST depth of a reliable topic on both sides: deeper where a publisher sends a burst in one callback
    depth: int = 10

    @property
    def package(self) -> str:
        return self.type.split('/')[0]

    @property
    def message(self) -> str:
        return self.type.split('/')[-1]


@dataclass(frozen=True)
class Contract:
    version: int
    frame_id: str
    joint_name: str
    topics: dict[str, Topic]
    path: Path

    def topic(self, name: str) -> Topic:
        try:
            return self.topics[name]
        except KeyError:
            raise ContractError(f'topic {name!r} is not in the interface contract {self.path}') from None

    def published_by(self, node: str) -> list[Topic]:
        return [t for t in self.topics.values() if node in (t.publisher, t.alt_publisher)]


def contract_path() -> Path:
    try:
        return share_path('msg_defs/topics.yaml')
    except ShareFileNotFound as e:
        raise ContractError(str(e)) from None


@functools.cache
def load_contract(path: str | None = None) -> Contract:
    """Parse and check the contract (cached)."""
    p = Path(path) if path else contract_path()
    try:
        raw: Any = yaml.safe_load(p.read_text())
        topics = {}
        for t in raw['topics']:
            topic = Topic(
                name=t['name'],
                type=t['type'],
                unit=str(t['unit']),
                rate_hz=float(t['rate_hz']),
                publisher=t['publisher'],
                subscribers=tuple(t.get('subscribers') or ()),
                description=t['description'],
                qos=t.get('qos', 'reliable'),
                alt_publisher=t.get('alt_publisher'),
                depth=int(t.get('depth', 10)),
            )
            if topic.name in topics:
                raise ContractError(f'{p}: topic {topic.name} listed twice')
            if topic.qos not in ('reliable', 'transient_local'):
                raise ContractError(f'{p}: topic {topic.name}: qos {topic.qos!r} is not reliable|transient_local')
            if topic.depth < 1:
                raise ContractError(f'{p}: topic {topic.name}: depth {topic.depth} must be at least 1')
            topics[topic.name] = topic
        return Contract(int(raw['contract_version']), raw['frame_id'], raw['joint_name'], topics, p)
    except (KeyError, TypeError, ValueError, yaml.YAMLError) as e:
        raise ContractError(f'{p}: malformed interface contract ({type(e).__name__}: {e})') from None


#: the payload [kg] the wrist is rated for at its lever (0.09 m): every place that takes one checks it against this.
#: Wider than the pre-load calibration's 0-0.7 kg (core.plant.preload.CALIBRATION_PAYLOAD_KG), on purpose: up to
#: 1.5 kg the simulated wrist stays inside its wire model (no wire-load bound, no over-temperature in 126 s closed
#: loops), and a heavier payload can follow a smaller reference; the Sec. 6.1 sine's top is out of reach at 1.5 kg
#: (doc/explanation/model.md, "Two payload ranges")
PAYLOAD_RANGE_KG = (0.0, 1.5)

#: the largest magnitude a measured sample of each kind can have and still be one (readers drop and count the rest):
#: temperatures in degC, K or degF, angles in rad or degrees, commands in V (a TEM driver's are within +-24 V), the
#: payload in kg. One 1e300 overflowed diagnose's fit; one 1e6 rad angle refused a bag or read as a 1e8 % error
IMPOSSIBLE = {'temperature': 1000.0, 'joint': 400.0, 'float': 1000.0}


def joint_positions(msgs: Any, joint_name: str | None = None) -> list[float]:
    """The wrist's angle [rad] in each sensor_msgs/JointState of ``msgs``: the position of ``joint_name`` (default
    the contract's) where a message names it -- a robot's /joint_states may carry several joints, in any order --
    else the only one; NaN where a message has no such position (a driver that sends velocities only).

    ContractError when a message of several joints names none ``joint_name``: taking its first joint was a guess
    that read another joint's angle as the wrist's without a word."""
    name = load_contract().joint_name if joint_name is None else joint_name
    out = []
    for m in msgs:
        names = list(m.name)
        if name in names:
            i = names.index(name)
        elif len(names) <= 1:
            i = 0
        else:
            raise ContractError(
                f'sensor_msgs/JointState names the joints {names}, none of them {name!r}: give the '
                "wrist's with --joint NAME"
            )
        out.append(float(m.position[i]) if len(m.position) > i else float('nan'))
    return out


@dataclass(frozen=True)
class Recording:
    """How a bag recorded on another rig names the contract's topics and the wrist's joint (``--topic``,
    ``--joint``), so that it reads as if it followed the contract."""

    topics: Mapping[str, str] = field(default_factory=dict)  # contract topic -> recorded topic
    joint: str | None = None  # the wrist's joint in its JointState (None: the contract's)

    @classmethod
    def from_options(cls, topic_specs: Iterable[str] | None = None, joint: str | None = None) -> Recording:
        """From ``CONTRACT=RECORDED`` strings; ContractError names a malformed, unknown or doubled one."""
        known = load_contract().topics
        out: dict[str, str] = {}
        for spec in topic_specs or ():
            name, sep, recorded = (x.strip() for x in spec.partition('='))
            if not sep or not name.startswith('/') or not recorded.startswith('/'):
                raise ContractError(f'--topic {spec!r}: give CONTRACT=RECORDED, e.g. /wrist/joint_states=/joint_states')
            if name not in known:
                raise ContractError(
                    f'--topic {spec!r}: {name} is not a contract topic (one of {", ".join(sorted(known))})'
                )
            if name in out or recorded in out.values():
                raise ContractError(f'--topic {spec!r}: {name if name in out else recorded} is mapped twice')
            out[name] = recorded
        if joint is not None and not joint.strip():
            raise ContractError('--joint needs a joint name')
        return cls(out, joint)

    def recorded(self, topics: Iterable[str]) -> list[str]:
        """The names under which ``topics`` (contract names) were recorded."""
        return [self.topics.get(t, t) for t in topics]

    def as_contract(self, data: Mapping[str, Any]) -> dict[str, Any]:
        """``data`` keyed by recorded topic -> keyed by contract topic."""
        back = {v: k for k, v in self.topics.items()}
        return {back.get(k, k): v for k, v in data.items() if k in back or k not in self.topics}


__all__ = [
    'IMPOSSIBLE',
    'PAYLOAD_RANGE_KG',
    'Contract',
    'ContractError',
    'Recording',
    'Topic',
    'contract_path',
    'joint_positions',
    'load_contract',
]
