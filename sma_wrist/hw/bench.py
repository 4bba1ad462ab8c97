"""Streaming benchmark: emulator (1 kHz, real time) -> pty -> SerialLink reader -> parser.

``bench_bridge(duration_s)`` runs the device emulator in a thread on a pty and the
bridge's serial link (reader thread, pyserial, protocol parser) on the other end, and
reports what arrived: samples sent/received, lost (sequence gaps), reordered/repeated,
latency from the emulator queueing a line to the link parsing it (monotonic ms, after 1 s warm-up, p50/p95/p99/max) and
the achieved rate. Both ends share one Python process (GIL), as the in-process
test set-up does; the ROS side is not included (see doc/explanation/protocol.md for numbers).
"""

from __future__ import annotations

import os
import queue
import tempfile
import time
from typing import Any

import numpy as np

from sma_wrist.hw import protocol as P
from sma_wrist.hw.emulator import DeviceEmulator, EmulatorConfig
from sma_wrist.hw.link import SerialLink

WARMUP_S = 1.0  # latency is not counted for the first second (bytes written before the port opened)


def bench_bridge(duration_s: float = 60.0, rate_hz: float = 1000.0) -> dict[str, Any]:
    """Stream for ``duration_s`` wall seconds; returns counts, latency percentiles [ms] and rate [Hz]."""
    with tempfile.TemporaryDirectory() as d:
        link_path = os.path.join(d, 'wrist')
        emu = DeviceEmulator(EmulatorConfig(rate_hz=rate_hz), link=link_path, log_sent=True)
        emu.start()
        link = SerialLink(link_path)
        link.start()
        sent_at: dict[int, float] = {}
        latencies: list[float] = []
        seq = P.SequenceTracker()
        received = 0
        first_t = last_t = None
        n_steady = 0
        t_start = time.monotonic()
        t_end = t_start + duration_s
        log = emu.sent_log
        assert log is not None
        k = 0
        try:
            while time.monotonic() < t_end:
                try:
                    kind, t_rx, f = link.events.get(timeout=0.05)
                except queue.Empty:
                    continue
                while k < len(log):  # index what the emulator has written so far
                    sent_at[log[k][1].seq] = log[k][0]
                    k += 1
                if kind != 'frame' or not isinstance(f, P.Sample):
                    continue
                received += 1
                seq.update(f.seq)
                t0 = sent_at.pop(f.seq, None)
                if t0 is not None and t_rx > t_start + WARMUP_S:  # after the stale pre-open backlog
                    latencies.append(t_rx - t0)
                if t_rx > t_start + WARMUP_S:  # rate over the steady part
                    first_t = first_t if first_t is not None else t_rx
                    last_t = t_rx
                    n_steady += 1
        finally:
            link.stop()
            emu.stop()
        lat = np.array(latencies) * 1e3 if latencies else np.array([np.nan])
        span = (last_t - first_t) if (first_t is not None and last_t is not None) else 0.0
        st = link.parser.stats
        return {
            'duration_s': duration_s,
            'rate_hz_configured': rate_hz,
            'samples_sent': emu.stats.samples_sent,
            'samples_received': received,
            'dropped': seq.lost,
            'reordered_or_repeated': seq.backwards,
            'rejected_lines': st.rejected_lines,
            'emulator_bytes_dropped': emu.stats.bytes_dropped,
            'latency_ms_p50': float(np.percentile(lat, 50)),
            'latency_ms_p95': float(np.percentile(lat, 95)),
            'latency_ms_p99': float(np.percentile(lat, 99)),
            'latency_ms_max': float(lat.max()),
            'achieved_rate_hz': (n_steady - 1) / span if span > 0 else 0.0,
            'latency_samples': len(latencies),
        }


if __name__ == '__main__':
    import json
    import sys

    print(json.dumps(bench_bridge(float(sys.argv[1]) if len(sys.argv) > 1 else 60.0), indent=2))
