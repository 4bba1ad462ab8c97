"""Measure the headline figures of the documentation and write ``doc/validation/results.json``.

Every figure on the validation page (and in the README's results block) comes from one command run here, and
each row of results.json keeps the exact command, its wall and CPU time, the date, the git commit and the machine.
The docs build renders the page from the JSON (``doc/refgen.py``); nothing is typed by hand.

    python3 doc/validation/measure.py                     # every run (~10 min of CPU), rewrites results.json
    python3 doc/validation/measure.py --only family       # one run, merged into the existing results.json
    python3 doc/validation/measure.py --readme            # rewrite README.md's results block from results.json
    python3 doc/validation/measure.py --check-readme      # exit 1 when README.md's block is not the JSON's

Run from anywhere; commands run in the repository root with its ``sma_wrist`` first on PYTHONPATH and write
their outputs under ``runs/validation/`` (ignored by git).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import resource
import shlex
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
DOC = HERE.parent
ROOT = DOC.parent
sys.path.insert(0, str(DOC))
sys.path.insert(0, str(ROOT))  # the checkout's sma_wrist (the tables' conversion), also when an installed copy exists

import refgen  # noqa: E402  (the renderer the docs build uses)

OUT = 'runs/validation'
F = 'test/data/flexinol'
HF = 'test/data/sma_react/NiTiHf'
CO = 'test/data/sma_react/NiTiCo'
TEC = f'{OUT}/tec_chamber'
#: the off-model plants of the tracking table (sma_wrist.plants.loop.CASES), all at 0.3 kg
OFF_MODEL_CASES = ('sensors', 'T-10', 'T+5', 'stroke x1.3', 'TEM gain -30%', 'phase_fraction')


def _tec_volts() -> None:
    """The Peltier logs with their PWM duty as the mean drive voltage (sma_wrist.identify.thermal.tec_chamber_volts)."""
    from sma_wrist.identify.thermal import tec_chamber_volts

    dst = ROOT / TEC
    dst.mkdir(parents=True, exist_ok=True)
    for name in ('run40', 'run39', 'run16'):
        tec_chamber_volts(ROOT / 'test/data/tec_chamber' / f'{name}.csv', dst / f'{name}.csv')


def _hysteresis(d: dict[str, Any]) -> dict[str, Any]:
    """The figures of `identify hysteresis --json`: SD-GPI RMS per load (in-sample), held-out, the built-in set's."""
    return {
        'model': d['model'],
        'in_sample_rms_pct': d['fit']['overall_rms_pct'],
        'per_load': [
            {'stress_MPa': r['stress_MPa'], 'sdgpi_rms_pct': r['sdgpi_rms_pct'], 'gpi_rms_pct': r['gpi_rms_pct']}
            for r in d['fit']['per_load']
        ],
        'holdout': [
            {
                'file': Path(r['file']).name,
                'stress_MPa': r['stress_MPa'],
                'rms_pct': r['rms_pct'],
                'max_pct': r['max_pct'],
            }
            for r in d['holdout']
        ],
        'before_rms_pct': [r['rms_pct'] for r in d['before']['per_load']],
    }


def _thermal(d: dict[str, Any]) -> dict[str, Any]:
    before = {e['record']: e['faces']['T1']['rms_C'] for e in d['before']}
    return {
        'holdout': [
            {'record': e['record'], 'rms_C': e['faces']['T1']['rms_C'], 'table_4_9_rms_C': before.get(e['record'])}
            for e in d['holdout']
            if e['mode'] == 'holdout-file'
        ],
        'warnings': d['warnings'],
    }


def _loops(d: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [
        {k: r[k] for k in ('case', 'mode', 'payload_kg', 'max_error_pct', 'rms_error_pct', 'reversals_per_s')}
        for r in d
    ]


def _sweep(d: dict[str, Any]) -> dict[str, Any]:
    keep = ('group', 'controller', 'loops', 'median_max_error_pct', 'p95_max_error_pct', 'share_under_15_pct')
    return {'loops': d['loops'], 'summary': [{k: s[k] for k in keep} for s in d['summary']]}


def _wire(d: dict[str, Any]) -> dict[str, Any]:
    w = d['measured_wire']
    return {
        'preload_elongation_mm': w['wire']['preload_elongation_mm'],
        'window_C': w['wire']['window_C'],
        'runs': [
            {k: r[k] for k in ('case', 'controller', 'max_error_pct', 'rms_error_pct', 'hottest_muscle_C')}
            for r in w['runs']
        ],
    }


#: id -> (what it measures, argv after the interpreter, extractor of the JSON output, set-up before it)
RUNS: dict[str, tuple[str, list[str], Callable[[Any], Any], Callable[[], None] | None]] = {
    'tracking_nominal': (
        'tracking error on the nominal plant, Sec. 6.1 sine, 126 s, 0.1 / 0.3 / 0.6 kg',
        ['-m', 'sma_wrist.plants.loop', '--cases', 'nominal', '--payloads', '0.1,0.3,0.6', '--json'],
        _loops,
        None,
    ),
    'tracking_off_model': (
        "tracking error on named plants that are not the controllers' model, 0.3 kg",
        ['-m', 'sma_wrist.plants.loop', '--cases', ','.join(OFF_MODEL_CASES), '--payloads', '0.3', '--json'],
        _loops,
        None,
    ),
    'family': (
        'tracking error over 40 sampled off-model plants (seed 1), each at its sampled 0.1-0.6 kg payload',
        [
            '-m',
            'sma_wrist',
            'sweep',
            '--plants',
            '40',
            '--seed',
            '1',
            '--workers',
            '1',
            '--out',
            f'{OUT}/sweep',
            '--quiet',
            '--json',
        ],
        _sweep,
        None,
    ),
    'measured_wire': (
        'the measured Flexinol wire identified and run in the node graph (TEMs rated 120 degC)',
        ['-m', 'sma_wrist', 'bench', '--section', 'measured_wire', '--json'],
        _wire,
        None,
    ),
    'identify_flexinol': (
        'Flexinol wire (test/data/flexinol): fitted at 50-172 MPa, 200 MPa held out',
        [
            '-m',
            'sma_wrist',
            'identify',
            'hysteresis',
            f'{F}/50MPa.txt',
            f'{F}/100MPa.txt',
            f'{F}/150MPa.txt',
            f'{F}/172MPa.txt',
            '--holdout',
            f'{F}/200MPa.txt',
            '--no-loo',
            '--no-plots',
            '--json',
            '--out',
            f'{OUT}/flexinol',
        ],
        _hysteresis,
        None,
    ),
    'identify_nitihf': (
        'NiTiHf (test/data/sma_react/NiTiHf): 5 loads fitted, 200 MPa held out',
        [
            '-m',
            'sma_wrist',
            'identify',
            'hysteresis',
            f'{HF}/7MPa.txt',
            f'{HF}/50MPa.txt',
            f'{HF}/100MPa.txt',
            f'{HF}/300MPa.txt',
            f'{HF}/400MPa.txt',
            '--holdout',
            f'{HF}/200MPa.txt',
            '--no-loo',
            '--no-plots',
            '--json',
            '--out',
            f'{OUT}/nitihf',
        ],
        _hysteresis,
        None,
    ),
    'identify_nitico': (
        'NiTiCo (test/data/sma_react/NiTiCo): 3 loads fitted, 200 MPa held out',
        [
            '-m',
            'sma_wrist',
            'identify',
            'hysteresis',
            f'{CO}/7MPa.txt',
            f'{CO}/50MPa.txt',
            f'{CO}/150MPa.txt',
            '--holdout',
            f'{CO}/200MPa.txt',
            '--no-loo',
            '--no-plots',
            '--json',
            '--out',
            f'{OUT}/nitico',
        ],
        _hysteresis,
        None,
    ),
    'identify_nitipd': (
        'NiTiPd (test/data/nitipd): one raw export of five loads, all fitted (in-sample)',
        [
            '-m',
            'sma_wrist',
            'identify',
            'hysteresis',
            'test/data/nitipd/NiTiPd_Characterization.txt',
            '--length-mm',
            '200',
            '--no-loo',
            '--no-plots',
            '--json',
            '--out',
            f'{OUT}/nitipd',
        ],
        _hysteresis,
        None,
    ),
    'identify_thermal': (
        'a real Peltier module (test/data/tec_chamber): fitted on run40, runs 39 and 16 held out',
        [
            '-m',
            'sma_wrist',
            'identify',
            'thermal',
            f'{TEC}/run40.csv',
            '--holdout',
            f'{TEC}/run39.csv',
            f'{TEC}/run16.csv',
            '--columns',
            'u=u_V,T1=oven_c',
            '--sample-period-s',
            '1',
            '--dt',
            '1',
            '--no-plots',
            '--json',
            '--out',
            f'{OUT}/tec_chamber/fit',
        ],
        _thermal,
        _tec_volts,
    ),
}


def shown(argv: list[str]) -> str:
    """The command as a user types it: ``sma-wrist ...`` for the package's CLI."""
    if argv[:2] == ['-m', 'sma_wrist']:
        return shlex.join(['sma-wrist'] + argv[2:])
    return shlex.join(['python3'] + argv)


def _git(*args: str) -> str:
    try:
        return subprocess.run(['git', *args], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return ''


def machine() -> dict[str, Any]:
    cpu = ''
    try:
        cpu = next(
            (
                ln.split(':', 1)[1].strip()
                for ln in Path('/proc/cpuinfo').read_text().splitlines()
                if ln.startswith('model name')
            ),
            '',
        )
    except OSError:
        pass
    try:
        load = os.getloadavg()[0]
    except OSError:
        load = None
    return {
        'cpu': cpu or platform.processor(),
        'cpu_count': os.cpu_count(),
        'system': platform.platform(),
        'python': platform.python_version(),
        'load_1min_at_start': load,
    }


def row_stamp() -> dict[str, Any]:
    """When a row's command started (UTC, to the minute) and the machine with its load at that moment."""
    return {'date': datetime.datetime.now(datetime.timezone.utc).strftime('%Y-%m-%d %H:%M UTC'), 'machine': machine()}


def run_one(name: str) -> dict[str, Any]:
    what, argv, extract, prepare = RUNS[name]
    if prepare:
        prepare()
    env = {
        **os.environ,
        'PYTHONPATH': os.pathsep.join(
            [str(ROOT)] + [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep) if p]
        ),
        'SMA_WRIST_BENCH_DIR': str(ROOT / OUT / 'bench'),
    }
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    print(f'[measure] {name}: {shown(argv)}', file=sys.stderr, flush=True)
    p = subprocess.run([sys.executable, *argv], cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f'measure: {name} failed (exit {p.returncode}):\n{p.stderr[-3000:]}')
    try:
        out = json.loads(p.stdout)
    except json.JSONDecodeError as e:
        raise SystemExit(f'measure: {name} printed no JSON ({e}):\n{p.stdout[-2000:]}') from None
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    print(f'[measure] {name}: {wall:.0f} s wall, {cpu:.0f} s CPU', file=sys.stderr, flush=True)
    return {
        'what': what,
        'command': shown(argv),
        'wall_s': round(wall, 1),
        'cpu_s': round(cpu, 1),
        'result': extract(out),
    }


def measure(names: list[str]) -> dict[str, Any]:
    old = json.loads(refgen.RESULTS.read_text()) if refgen.RESULTS.exists() else {}
    runs = dict(old.get('runs', {})) if len(names) < len(RUNS) else {}
    code = {
        'commit': _git('rev-parse', '--short=12', 'HEAD'),
        'dirty': bool(_git('status', '--porcelain', '--untracked-files=no')),
    }
    for n in names:
        started = row_stamp()  # this row's start and load, not the whole run's (~10 min)
        runs[n] = {**run_one(n), 'date': started['date'], **code, 'machine': started['machine']}
    return {'about': 'written by doc/validation/measure.py; rendered by doc/refgen.py', 'runs': runs}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        '--only',
        action='append',
        choices=sorted(RUNS),
        help='run only these (repeatable); the others keep their figures from results.json',
    )
    ap.add_argument('--readme', action='store_true', help="rewrite README.md's results block from results.json")
    ap.add_argument('--check-readme', action='store_true', help="exit 1 when README.md's block differs")
    a = ap.parse_args(argv)
    readme = ROOT / 'README.md'
    if a.readme or a.check_readme:
        try:
            text = readme.read_text()
            new = refgen.replace_readme_block(text, json.loads(refgen.RESULTS.read_text()))
        except (OSError, ValueError) as e:
            print(f'error: {e}', file=sys.stderr)
            return 2
        if a.check_readme:
            if new != text:
                print(
                    "README.md: the results block is not results.json's; run python3 doc/validation/measure.py "
                    '--readme',
                    file=sys.stderr,
                )
                return 1
            return 0
        readme.write_text(new)
        return 0
    results = measure(a.only or list(RUNS))
    refgen.RESULTS.write_text(json.dumps(results, indent=1) + '\n')
    print(f'wrote {refgen.RESULTS}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
