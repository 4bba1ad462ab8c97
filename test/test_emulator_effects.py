"""Effects the emulated device starts mid-run (``sma-wrist emulate-device --effect``): what the device reports is
the unaffected device's until the onset, and changes after it."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sma_wrist.cli_options import emulator_arguments
from sma_wrist.hw import protocol as P
from sma_wrist.hw.emulator import DeviceEmulator, Effect, config_from_args

RATE_HZ = 100.0
ONSET_S = 1.0
ROOT = Path(__file__).resolve().parents[1]


def _readings(effects: list[str], seconds: float = 2.5, drive: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(t [s], physical readings (K, 5): 4 temperatures [degC], angle [rad]) of a device at 100 Hz driven at +8 / -4 V."""
    ap = argparse.ArgumentParser()
    emulator_arguments(ap)
    args = ['--rate-hz', str(RATE_HZ), '--watchdog-s', '100', '--seed', '3']
    for e in effects:
        args += ['--effect', e]
    cfg = config_from_args(ap.parse_args(args))
    emu = DeviceEmulator(cfg)
    if drive:
        emu.receive(P.encode(P.Command(0, 8000, -4000)))
    parser = P.Parser()
    samples = [f for f in parser.feed(emu.emit(int(seconds * RATE_HZ))) if isinstance(f, P.Sample)]
    t = np.array([s.t_us for s in samples]) * 1e-6
    phys = [cfg.calibration.to_physical(s.adc) for s in samples]
    return t, np.array([[*T, q] for T, q in phys])


@pytest.fixture(scope='module')
def clean() -> tuple[np.ndarray, np.ndarray]:
    return _readings([])


@pytest.mark.parametrize(
    'spec,channel,smallest_change',
    [
        ('offset:T1:3@1', 0, 2.5),  # degC: a thermocouple coming loose
        ('gain:q:0.1@1', 4, 0.005),  # rad
        ('lag:T2:2@1', 1, 0.02),  # degC: the reading falls behind a muscle that cools
        ('tem_weak:plant:0.3@1', 0, 0.05),  # degC: the TEMs heat less
        ('payload:plant:0.4@1', 4, 1e-3),  # rad: a heavier wrist sags
        ('transition_drift:plant:10@1', 4, 1e-3),  # rad: the wires transform elsewhere
    ],
)
def test_an_effect_changes_what_the_device_reports_from_its_onset_only(clean, spec, channel, smallest_change):
    t, ref = clean
    _, x = _readings([spec])
    before = t < ONSET_S - 1e-9
    assert np.array_equal(x[before], ref[before])  # to the count: the same device until the onset
    assert np.abs(x[~before, channel] - ref[~before, channel]).max() > smallest_change


def test_the_onset_counts_from_the_first_command():
    """A device not yet driven by a host has no effect however long it has been on: the onset is the same time into
    every run, whenever the host started."""
    _, ref = _readings([], drive=False)
    _, x = _readings(['offset:T1:3@1'], drive=False)
    assert np.array_equal(x, ref)


def test_a_bad_effect_spec_is_refused_with_what_a_spec_looks_like():
    for bad in ('offset:T1:3', 'offset:T3:3@1', 'wobble:T1:3@1', 'offset:T1:x@1', 'tem_weak:plant:1.5@1', 'lag:q:-1@0'):
        with pytest.raises(ValueError, match='--effect'):
            Effect.parse(bad)
    assert Effect.parse('transition_drift:plant:6@60+120') == Effect('transition_drift', 'plant', 6.0, 60.0, 120.0)
    r = subprocess.run(
        [sys.executable, '-m', 'sma_wrist', 'emulate-device', '--effect', 'offset:T1@60', '--duration', '0.1'],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 2 and 'KIND:CHANNEL:VALUE@ONSET_S' in r.stdout + r.stderr
    assert 'Traceback' not in r.stderr
