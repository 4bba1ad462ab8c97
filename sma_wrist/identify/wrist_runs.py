"""An identified wire in the node graph: closed loops on the built-in wire moved hotter (:func:`hot_wire_runs`) and on
a measured wire identified from its loops (:func:`measured_wire_runs`), with :mod:`sma_wrist.identify.wrist`'s
windows (``sma-wrist bench --section identify_wrist / measured_wire``). Above both ``identify.hysteresis``, which it
runs, and ``identify.wrist``, which that uses.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.identify.wrist import (
    operating_window,
    rated_tems,
    shifted_wire,
    wire_transitions,
    wrist_params,
    write_wrist_params,
)

#: a closed-loop case: label, params file (None: the defaults), the problems wrist_params reported,
#: extra node parameters (None: none), the controllers to run on it
_Case = tuple[str, Any, list[str], dict[str, Any] | None, tuple[str, ...]]


def hot_wire_runs(
    controllers: tuple[str, ...] = ('inverse_adaptive', 'direct_adaptive', 'pid'),
    dT_C: float = 20.0,
    duration_s: float = 126.0,
    tem_tops_C: tuple[float, ...] = (80.0, 120.0),
    progress: Any = None,
    png: str | None = None,
) -> dict[str, Any]:
    """Closed loops (embedded runtime) on the built-in wire moved up ``dT_C`` with :func:`wrist_params`.

    For each TEM rating in ``tem_tops_C`` (80 degC: the seed's TEMs) and each controller:
    max and RMS tracking error over the last reference cycle in % of the reference range
    (runs.run_metrics), the hottest measured muscle temperature and the problems
    :func:`wrist_params` reported. Also the built-in wire with the defaults, for reference.
    ``png``: angle, reference and error per case (``<png stem>_<case>.png``, controllers overlaid).
    """
    import tempfile

    from sma_wrist.core.hysteresis.default_params import default_sdgpi
    from sma_wrist.core.hysteresis.params_file import save_hysteresis
    from sma_wrist.core.thermal.params_file import write_thermal_file

    wire = shifted_wire(default_sdgpi(), dT_C)
    tr = wire_transitions(wire)
    out: dict[str, Any] = {
        'wire': {
            'dT_C': dT_C,
            'M_f_C': tr['M_f'],
            'A_f_C': tr['A_f'],
            'load_kgf': tr['load_kgf'],
            'window_C': list(operating_window(wire)),
        },
        'runs': [],
    }
    with tempfile.TemporaryDirectory(prefix='sma_hot_wire_') as d:
        hf = save_hysteresis(Path(d) / 'hysteresis.yaml', wire)
        cases: list[_Case] = [('built-in wire, defaults', None, [], None, controllers)]
        for top in tem_tops_C:
            tems = rated_tems(top)
            tf = write_thermal_file(Path(d) / f'tems_{top:g}C.yaml', tems)
            nodes, problems = wrist_params(hf, wire, tf, tems.window_C)
            cases.append(
                (
                    f'hot wire, TEMs rated {top:g} degC',
                    write_wrist_params(Path(d) / f'wrist_{top:g}C.yaml', nodes, problems),
                    problems,
                    None,
                    controllers,
                )
            )
        _closed_loops(cases, duration_s, Path(d), out, progress, png)
    return out


#: the laws of direct_adaptive and pid without their reference leads (doc/explanation/controllers.md)
WITHOUT_LEADS = {'adaptive_controller': {'direct_reference_lead_s': 0.0, 'pid_reference_lead_s': 0.0}}


def measured_wire_runs(
    files: list[str | Path],
    controllers: tuple[str, ...] = ('inverse_adaptive', 'direct_adaptive', 'pid'),
    duration_s: float = 126.0,
    tem_top_C: float = 120.0,
    model: str = 'saturating',
    progress: Any = None,
    png: str | None = None,
) -> dict[str, Any]:
    """A wire identified from measured isobaric loops (``files``: ``sma-wrist identify hysteresis`` with the
    load law ``model``, the one ``auto`` chose for the Flexinol data, without its leave-one-out) run in the node graph (embedded runtime, 0.3 kg) on TEMs rated ``tem_top_C`` with
    :func:`wrist_params`' windows: each controller, and direct_adaptive / pid also without their reference
    leads. Rows as :func:`hot_wire_runs`' (doc/howto/identify_wire.md)."""
    import tempfile

    from sma_wrist.core.thermal.params_file import write_thermal_file
    from sma_wrist.identify.hysteresis import Options, run

    out: dict[str, Any] = {'runs': []}
    with tempfile.TemporaryDirectory(prefix='sma_measured_wire_') as d:
        tf = write_thermal_file(Path(d) / f'tems_{tem_top_C:g}C.yaml', rated_tems(tem_top_C))
        doc = run(
            Options([str(f) for f in files], out=d, loo=False, plots=False, model=model, thermal_file=str(tf)),
            progress=progress or (lambda m: None),
        )
        wp = doc['wrist_params']
        if not wp['file']:
            raise ParameterError(f'no wrist parameters for this wire: {"; ".join(wp["problems"])}')
        out['wire'] = {
            'window_C': wp['window_C'],
            'problems': wp['problems'],
            'files': [str(f) for f in files],
            'preload_elongation_mm': wp['preload_elongation_mm'],
        }
        cases: list[_Case] = [
            (f'measured wire, TEMs rated {tem_top_C:g} degC', wp['file'], wp['problems'], None, controllers)
        ]
        with_leads = tuple(c for c in controllers if c in ('direct_adaptive', 'pid'))
        if with_leads:
            cases.append(
                (
                    'the same, direct and pid without their reference leads',
                    wp['file'],
                    wp['problems'],
                    WITHOUT_LEADS,
                    with_leads,
                )
            )
        _closed_loops(cases, duration_s, Path(d), out, progress, png)
    return out


def _closed_loops(
    cases: list[_Case], duration_s: float, work: Path, out: dict[str, Any], progress: Any, png: str | None
) -> None:
    """Each case under each of its controllers at 0.3 kg: rows into ``out['runs']``, one PNG per case."""
    from sma_wrist import runtime

    runtime.activate()
    from sma_wrist.closed_loop import run_closed_loop
    from sma_wrist.runs import plot_runs

    figures: list[tuple[str, list[Any], list[str]]] = []
    for label, pf, problems, extra, names in cases:
        traces: list[Any] = []
        for ctrl in names:
            s = run_closed_loop(
                ctrl,
                0.3,
                duration_s,
                bag=work / f'bag_{len(out["runs"])}',
                params_files=[pf] if pf is not None else [],
                extra_params=extra,
            )
            m, r = s.metrics, s.run
            row = {
                'case': label,
                'controller': ctrl,
                'max_error_pct': m['max_error_pct'],
                'rms_error_pct': m['rms_error_pct'],
                'window': m['window'],
                'wall_s': s.wall_s,
                'hottest_muscle_C': float(np.nanmax(r.temperature_C)),
                'problems': problems,
            }
            out['runs'].append(row)
            traces.append(r)
            if progress is not None:
                progress(
                    f'{label}, {ctrl}: max {row["max_error_pct"]:.1f} %, RMS {row["rms_error_pct"]:.1f} % '
                    f'(last cycle), hottest muscle {row["hottest_muscle_C"]:.1f} degC'
                )
        figures.append((label, traces, list(names)))
    if png:  # one figure per case, its controllers overlaid (runs.plot_runs)
        out['png'] = []
        for k, (label, traces, names) in enumerate(figures):
            path = f'{Path(png).with_suffix("")}_{k}.png'
            plot_runs(traces, names, path, label)
            out['png'].append(path)
