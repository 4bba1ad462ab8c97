"""tem_controller: desired muscle temperatures -> TEM drive commands (Eqs. 5.38-5.47).

One node drives both layers (two-layer arrangement: one TEM layer per muscle, weights
(1, 0) of Eq. 5.47). The feedback-linearising law needs both faces of each module; only
the muscle face is measured, so the exchanger face comes from an observer: the heat
balance (Eqs. 4.13-4.14) integrated with the commands this node sent, its muscle face
reset to each measurement.

It computes when a fresh temperature of both muscles has arrived (measurement-driven,
100 Hz with the default plant), using the latest desired temperatures.

Safety, in this order: no fresh measurement for ``stale_timeout_s`` -> 0 V (TEMs off) and
an ERROR on /diagnostics until data returns; no desired temperature yet or a stale one ->
0 V; a muscle above ``max_muscle_temperature_C`` may only be cooled; every command is
clipped to the driver rating [``u_min_V``, ``u_max_V``], and to what keeps every (measured or
observed) face of its layer inside the TEM's window over the protection horizon, predicted by
the heat balance (:class:`~sma_wrist.core.control.tem.DriveLimits`); every clip is reported.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from std_msgs.msg import Float64

from sma_wrist.core.control import tem_kernel
from sma_wrist.core.control.tem import (
    CHATTER_LIMIT_PER_S,
    CHATTER_RATE_FILTER_S,
    CHATTER_WINDOW_S,
    DriveLimits,
    TemControlParams,
    TemLoop,
)
from sma_wrist.core.errors import SmaWristError
from sma_wrist.core.thermal import heat_balance as th
from sma_wrist.core.thermal import online as thermal_online
from sma_wrist.core.thermal.params_file import load_thermal_file
from sma_wrist.nodes.common import (
    THERMAL_ADAPTATION_PARAMS,
    Freshness,
    Param,
    WristNode,
    finite,
    main_for,
    online_thermal,
)

LIMITS = th.ThermalParams()  # its u limits are the *hold* limits (doc/explanation/model.md)
DRIVE = DriveLimits()


class TemController(WristNode):
    PARAMS = (
        Param('gain_per_s', 1.0, 'k of the temperature error dynamics de/dt + k e = 0 (Eq. 5.42)', '1/s', (0.01, 50.0)),
        Param('rate_filter_s', 0.05, 'time constant of the filter on the estimated dT_d/dt', 's', (0.0, 10.0)),
        Param(
            'target_filter_s',
            0.5,
            'time constant of the prefilter on the desired temperatures (no TEM '
            'chattering on noise and target jumps; doc/explanation/controllers.md)',
            's',
            (0.0, 10.0),
        ),
        Param(
            'chatter_guard.limit_per_s',
            CHATTER_LIMIT_PER_S,
            'a TEM command changing sign more often than this (averaged over chatter_guard.window_s) switches '
            'the rate filter to chatter_guard.rate_filter_s until it is below half of it; 0: off '
            '(doc/explanation/controllers.md)',
            '1/s',
            (0.0, 50.0),
        ),
        Param(
            'chatter_guard.window_s',
            CHATTER_WINDOW_S,
            'chatter_guard: averaging time of the sign-change rate',
            's',
            (1.0, 600.0),
        ),
        Param(
            'chatter_guard.rate_filter_s',
            CHATTER_RATE_FILTER_S,
            'chatter_guard: the rate filter while engaged',
            's',
            (0.0, 10.0),
        ),
        Param('u_min_V', DRIVE.boost_min_V, 'most negative (cooling) drive command: driver rating', 'V', (-29.0, -1.0)),
        Param('u_max_V', DRIVE.boost_max_V, 'most positive (heating) drive command: driver rating', 'V', (1.0, 34.0)),
        Param(
            'predictive_protection',
            DRIVE.predictive,
            'allow a command while the heat balance predicts every face of its layer inside '
            '[face_min_C, face_max_C] over protection_horizon_s (else: the fixed switch at protect_above_C)',
        ),
        Param('face_min_C', DRIVE.face_min_C, 'TEM operating window, lower face limit', 'degC', (-40.0, 40.0)),
        Param('face_max_C', DRIVE.face_max_C, 'TEM operating window, upper face limit', 'degC', (40.0, 120.0)),
        Param(
            'protection_horizon_s', DRIVE.horizon_s, 'how far ahead the protection predicts the faces', 's', (0.1, 30.0)
        ),
        Param(
            'protect_above_C',
            DRIVE.protect_above_C,
            "predictive_protection false: above this face temperature a layer falls back to its TEM's hold limits "
            f"([{LIMITS.u_min_V:g}, {LIMITS.u_max_V:g}] V; a thermal_file's per TEM)",
            'degC',
            (30.0, 80.0),
        ),
        Param('max_muscle_temperature_C', 85.0, 'above this a muscle is only cooled', 'degC', (30.0, 120.0)),
        Param('stale_timeout_s', 0.25, 'measurement/target age that switches the TEMs off', 's', (0.01, 10.0)),
        Param(
            'thermal_file',
            '',
            'identified TEM heat balance for the law, observer and protection '
            '(sma-wrist identify thermal; empty: Table 4.9)',
            runtime=False,
        ),
        *THERMAL_ADAPTATION_PARAMS,
    )

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('tem_controller', **kwargs)
        # the model of the TEMs (law, observer, protection) with its own hold limits (each TEM's, where they differ)
        self.hold = load_thermal_file(self.p['thermal_file']) if self.p['thermal_file'] else LIMITS
        tem_kernel.warm_up()  # compile before the first sample, not inside the loop
        if online_thermal(self.p) is not None:
            thermal_online.warm_up()  # ... and the online estimate's, first called 2 s into a run
        self.loop = self._build_loop(None)
        self.T_meas = np.full(2, np.nan)
        self.T_d = np.full(2, np.nan)
        self.t_meas = [0.0, 0.0]  # stamp [s] of the latest measurement per muscle
        self.new_meas = [False, False]
        self._status: tuple[bool, bool, bool] | None = None  # (hot, saturated, fresh) last diagnosed
        self._chattering = False  # the chatter guard's state last reported
        self.meas = Freshness(self, ('muscle_1', 'muscle_2'))
        self.targets = Freshness(self, ('target_1', 'target_2'))
        self.pub_cmd = [self.publisher(f'/wrist/tem_{i}/command') for i in (1, 2)]
        for i in (1, 2):
            self.subscription(f'/wrist/muscle_{i}/temperature', lambda m, i=i: self._on_temperature(i, m))
            self.subscription(f'/wrist/muscle_{i}/temperature_desired', lambda m, i=i: self._on_target(i, m))
        self.watchdog = self.create_timer(0.05, self._check_stale)
        p = self.p
        waits = self.waiting_for(
            'the measured and desired muscle temperatures (/wrist/muscle_{1,2}/temperature, temperature_desired)'
        )
        self.get_logger().info(
            f'tem_controller: gain {p["gain_per_s"]:g} 1/s, drive {p["u_min_V"]:g}..{p["u_max_V"]:g} V, TEM faces kept '
            f'in {p["face_min_C"]:g}-{p["face_max_C"]:g} degC, online heat-balance estimate '
            f'{"on" if p["thermal_adaptation.enabled"] else "off"}; {waits} (0 V until both are fresh, and after '
            f'{p["stale_timeout_s"]:g} s without one)'
        )

    @property
    def observer(self) -> np.ndarray:
        """(1, 2 layers, 2 faces) observed TEM faces [degC]."""
        return self.loop.observer

    @property
    def command_V(self) -> np.ndarray:
        """(2,) commands in force [V]."""
        return self.loop.command_V

    def validate(self, values: Mapping[str, Any]) -> str | None:
        problem = super().validate(values)
        if problem is None and not values['face_min_C'] < values['face_max_C']:
            problem = f'face_min_C = {values["face_min_C"]} must be below face_max_C = {values["face_max_C"]}'
        return problem

    def _build_loop(self, old: TemLoop | None) -> TemLoop:
        p = self.p
        drive = DriveLimits(
            p['u_min_V'],
            p['u_max_V'],
            p['protect_above_C'],
            p['predictive_protection'],
            p['face_min_C'],
            p['face_max_C'],
            p['protection_horizon_s'],
        )
        thermal = replace(self.hold, u_min_V=p['u_min_V'], u_max_V=p['u_max_V'])  # the law's saturation
        law = TemControlParams(
            gain_per_s=p['gain_per_s'],
            rate_filter_s=p['rate_filter_s'],
            target_filter_s=p['target_filter_s'],
            chatter_limit_per_s=p['chatter_guard.limit_per_s'],
            chatter_window_s=p['chatter_guard.window_s'],
            chatter_rate_filter_s=p['chatter_guard.rate_filter_s'],
        )
        loop = TemLoop(thermal, law, drive, self.hold, p['max_muscle_temperature_C'], online=online_thermal(p))
        if old is not None:  # new gains and limits act on the same observed TEMs and command in force
            loop.observer, loop.command_V, loop.t_last = old.observer, old.command_V, old.t_last
            loop.take_guard_state(old)  # ... with the sign changes counted so far
            loop.estimator = old.estimator  # ... and keep what has been learnt of them
            if old.theta_used is not None and loop.estimator is not None:
                loop.use_estimate(old.theta_used)
        return loop

    def apply(self, changed: Mapping[str, Any]) -> None:
        self.loop = self._build_loop(self.loop)

    # -- inputs ------------------------------------------------------------------
    def _on_temperature(self, i: int, msg: Any) -> None:
        T = msg.temperature
        if not finite(T) or not (-50.0 <= T <= 200.0):
            self.reject_input(f'muscle_{i}/temperature', f'{T!r} degC is not a plausible temperature')
            return
        self.T_meas[i - 1] = T
        self.t_meas[i - 1] = self.stamp_s(msg)
        self.new_meas[i - 1] = True
        self.meas.mark(f'muscle_{i}')
        if all(self.new_meas):
            self.new_meas = [False, False]
            self._control()

    def _on_target(self, i: int, msg: Any) -> None:
        T = msg.temperature
        if not finite(T):
            self.reject_input(f'muscle_{i}/temperature_desired', f'non-finite target {T!r} degC')
            return
        self.T_d[i - 1] = T
        self.targets.mark(f'target_{i}')

    # -- control -----------------------------------------------------------------
    def _control(self) -> None:
        fresh = not self.targets.stale(self.p['stale_timeout_s'])
        try:
            res = self.loop.sample(max(self.t_meas), self.T_meas, self.T_d if fresh else None)
        except SmaWristError as e:
            self.diagnose('law', DiagnosticStatus.ERROR, f'TEM law failed, TEMs off: {e}')
            self._send(self.loop.off())
            return
        if res is None:
            return  # a repeated or out-of-order sample: the command in force stays
        if fresh:
            self._report(bool(res.hot.any()), bool(res.saturated.any()))
        if self.loop.chattering != self._chattering:
            self._report_chatter()
        self._send(res.command_V)

    def _report_chatter(self) -> None:
        on = self._chattering = self.loop.chattering
        g = self.loop.guard
        rate = 0.0 if g is None else float(g.rate.max())
        msg = (
            f'TEM commands change sign {rate:.2f} /s (> {self.p["chatter_guard.limit_per_s"]:g}): rate filter '
            f'{self.p["chatter_guard.rate_filter_s"]:g} s'
            if on
            else f'TEM command sign changes {rate:.2f} /s: rate filter {self.p["rate_filter_s"]:g} s'
        )
        self.diagnose(
            'chatter', DiagnosticStatus.WARN if on else DiagnosticStatus.OK, msg, {'sign_changes_per_s': f'{rate:.2f}'}
        )  # diagnose logs it too

    def _report(self, hot: bool, sat: bool) -> None:
        # diagnose publishes on change only; skip building its arguments while nothing changed
        if self._status == (hot, sat):
            return
        self._status = (hot, sat)
        self.diagnose(
            'over_temperature',
            DiagnosticStatus.ERROR if hot else DiagnosticStatus.OK,
            'muscle above limit: heating blocked' if hot else 'muscle temperatures below limit',
            {'T_1_C': f'{self.T_meas[0]:.2f}', 'T_2_C': f'{self.T_meas[1]:.2f}'},
        )
        self.diagnose(
            'saturation',
            DiagnosticStatus.WARN if sat else DiagnosticStatus.OK,
            'command clipped to the drive limits' if sat else 'commands within limits',
            routine=True,
        )
        self.diagnose('watchdog', DiagnosticStatus.OK, 'measurements and targets fresh')

    def _check_stale(self) -> None:
        stale = self.meas.stale(self.p['stale_timeout_s'])
        if stale and self.meas.seen_all():
            self._status = None  # the next good sample reports the recovery
            self.diagnose('watchdog', DiagnosticStatus.ERROR, f'no fresh {", ".join(stale)} temperature: TEMs off')
            self._send(self.loop.off())

    def _send(self, u: np.ndarray) -> None:
        for i in range(2):
            self.pub_cmd[i].publish(Float64(data=float(u[i])))


def main(args: list[str] | None = None) -> int:
    return main_for(TemController, args)


if __name__ == '__main__':
    raise SystemExit(main())
