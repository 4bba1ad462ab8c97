"""Start-up of the monitor's check worker process (``twin_monitor``'s ``worker: process``)."""

from __future__ import annotations

import os

from sma_wrist.monitor import ignore_interrupts


def start_worker(nice: int = 0) -> None:
    """A check worker's initializer: Ctrl-C left to the node that owns it (:func:`ignore_interrupts`), and its
    scheduling priority lowered by ``nice`` (Unix niceness, 0-19) so that on a busy machine a check takes the CPU
    the control loop leaves over rather than a share of the loop's: a check that falls behind is skipped, the
    loop is not slowed."""
    ignore_interrupts()
    if nice > 0 and hasattr(os, 'nice'):
        try:
            os.nice(int(nice))
        except OSError:  # not permitted here: the worker runs at the node's priority
            pass
