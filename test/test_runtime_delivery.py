"""The embedded runtime's optional delivery model (sma_wrist/runtime/delivery.py): latency and
jitter per delivery from a seeded generator, off by default."""

from __future__ import annotations

import numpy as np
import pytest

from sma_wrist.runtime.delivery import DeliveryModel
from sma_wrist.runtime.launch import Runtime


def _arrivals(delivery: DeliveryModel | None, n: int = 200) -> list[tuple[str, int, int]]:
    """(topic, index, arrival [ns]) of n messages on each of /a and /b, published together every 1 ms."""
    from rclpy.node import Node
    from std_msgs.msg import Int64

    log: list[tuple[str, int, int]] = []
    with Runtime(delivery=delivery) as rt:
        src = rt.add(Node('src'))
        pubs = {t: src.create_publisher(Int64, t, 10) for t in ('/a', '/b')}
        k = [0]

        def tick() -> None:
            if k[0] < n:
                for p in pubs.values():
                    p.publish(Int64(data=k[0]))
                k[0] += 1

        src.create_timer(0.001, tick)
        sink = rt.add(Node('sink'))
        for t in pubs:
            sink.create_subscription(Int64, t, lambda m, t=t: log.append((t, m.data, rt.steady_ns)), 100)
        rt.run_until(n * 0.001 + 0.1, until='steady')
    return log


def test_default_delivers_at_once_in_a_fixed_order():
    log = _arrivals(None)
    assert [(t, k) for t, k, _ in log] == [(t, k) for k in range(200) for t in ('/a', '/b')]
    assert all(t_ns == (k + 1) * 1_000_000 for _, k, t_ns in log)


def test_delivery_model_delays_and_reorders_across_topics_keeping_each_writers_order():
    log = _arrivals(DeliveryModel(latency_s=5e-4, jitter_s=2e-3, seed=3))
    for topic in ('/a', '/b'):
        ks = [k for t, k, _ in log if t == topic]
        assert ks == list(range(200))  # nothing lost, in order per writer/reader pair (RELIABLE DDS)
    delay = np.array([t_ns - (k + 1) * 1_000_000 for _, k, t_ns in log]) * 1e-9
    assert delay.min() >= 5e-4 - 1e-9 and 1e-3 < delay.mean() < 5e-3
    pos = {(t, k): i for i, (t, k, _) in enumerate(log)}
    b_first = sum(pos[('/b', k)] < pos[('/a', k)] for k in range(200))
    assert 20 < b_first < 180  # the pair published /a then /b is taken in either order
    assert _arrivals(DeliveryModel(latency_s=5e-4, jitter_s=2e-3, seed=3)) == log  # seeded: reproducible
    assert _arrivals(DeliveryModel(latency_s=5e-4, jitter_s=2e-3, seed=4)) != log


def test_bad_delivery_model_is_refused():
    with pytest.raises(ValueError, match='must be >= 0'):
        DeliveryModel(per_topic={'/clock': (-1e-3, 0.0)})


def test_closed_loop_with_dds_like_delivery_agrees_with_the_deterministic_run(tmp_path):
    """inverse_adaptive 0.3 kg, 12 s: the joint angle with the default delivery model (0.3 ms +
    Exp(1 ms) per hop, seed 1) stays within 0.5 % of the reference range of the deterministic run
    (measured 2026-11-24 with the measurements paired by stamp: 0.09 % seed 1, 0.10 % seed 2; 0.50-0.68 %
    with 3 ms + Exp(5 ms); the code before gave 0.10-0.11 %: 12 s end before the first reversal, so this
    is a smoke test of the model in the loop -- the arrival-order test is
    test_node_controllers.py::test_compensator_memory_takes_every_measured_tick_by_stamp_whatever_the_arrival_order)."""
    from sma_wrist.closed_loop import run_closed_loop

    det = run_closed_loop('inverse_adaptive', 0.3, 12.0, tmp_path / 'det').run
    jit = run_closed_loop('inverse_adaptive', 0.3, 12.0, tmp_path / 'jit', delivery=DeliveryModel(seed=1)).run
    q = np.interp(det.t, jit.t, jit.q)
    diff_pct = 100.0 * np.max(np.abs(q - det.q)) / np.ptp(det.q_d)
    assert 0.0 < diff_pct < 0.5  # the model did change the timing, and the loop does not care
