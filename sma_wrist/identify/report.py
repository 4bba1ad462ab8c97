"""Markdown report and PNG plots of a hysteresis identification (``--out DIR``).

Plots: ``loops.png`` (measured loop, identified SD-GPI and the model before fitting, per
stress; held-out stresses marked) and ``transitions.png`` (A_50 / M_50 and A_s..M_f against
stress: measured, before, fitted). Without matplotlib (extra ``plot``) the report says so.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.identify.io import REF_LENGTH_MM


def _plots(
    out: Path,
    doc: dict[str, Any],
    train: list[Any],
    hold: list[Any],
    y_fit: list[Any],
    y_hold: list[Any],
    before_name: str,
) -> list[str]:
    try:
        import matplotlib

        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        return []

    loops = [(lp, yf, False) for lp, yf in zip(train, y_fit)] + [(lp, yh, True) for lp, yh in zip(hold, y_hold)]
    n = len(loops)
    cols = min(3, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.2 * rows), squeeze=False)
    before = {(b['file'], b['stress_MPa']): b for b in doc['before']['per_load']}
    for ax, (lp, ym, held) in zip(axes.ravel(), loops):
        y = lp.strain * REF_LENGTH_MM
        ax.plot(lp.T_C, y / REF_LENGTH_MM * 100, '.', ms=2, color='0.4', label='measured')
        ax.plot(
            lp.T_C,
            ym / REF_LENGTH_MM * 100,
            '-',
            color='C3' if held else 'C0',
            lw=1.2,
            label='SD-GPI (held out)' if held else 'SD-GPI fit',
        )
        b = before.get((lp.source, lp.stress_MPa))
        title = f'{lp.stress_MPa:g} MPa' + (' (held out)' if held else '')
        if b:
            title += f'\nbefore: RMS {b["rms_pct"]:.0f} %'
        ax.set_title(title, fontsize=9)
        ax.set_xlabel('T [degC]')
        ax.set_ylabel('strain [%]')
    for ax in axes.ravel()[n:]:
        ax.axis('off')
    axes.ravel()[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / 'loops.png', dpi=110)
    plt.close(fig)

    tr = doc['transitions']
    s = np.array([lp.stress_MPa for lp in train + hold])
    s_tr = s[: len(train)]
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for key, col in (('A_50', 'C3'), ('M_50', 'C0'), ('A_f', 'C1'), ('M_f', 'C2')):
        ax.plot(s, [t[key] for t in tr['measured']], 'o', color=col, label=f'{key} measured')
        ax.plot(s_tr, [t[key] for t in tr['fitted']], '-', color=col, label=f'{key} SD-GPI')
        ax.plot(s, [t[key] for t in tr['before']], 'x:', color=col, alpha=0.6, label=f'{key} before')
    ax.set_xlabel('stress [MPa]')
    ax.set_ylabel('transition temperature [degC]')
    ax.set_title(f'measured (dots), identified SD-GPI (lines), before = {before_name} (x)', fontsize=8)
    ax.legend(fontsize=6, ncol=3, loc='best')
    fig.tight_layout()
    fig.savefig(out / 'transitions.png', dpi=110)
    plt.close(fig)
    return ['loops.png', 'transitions.png']


def _f(v: Any, fmt: str = '.2f') -> str:
    return 'n/a' if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, fmt)


def write_report(
    out: Path,
    doc: dict[str, Any],
    train: list[Any],
    hold: list[Any],
    y_fit: list[Any],
    y_hold: list[Any],
    before_model: Any,
    plots: bool = True,
) -> Path:
    """Write report.md (and the PNGs) into ``out``; returns the report's path."""
    out.mkdir(parents=True, exist_ok=True)
    pngs = _plots(out, doc, train, hold, y_fit, y_hold, before_model.name) if plots else []
    L = [
        '# Hysteresis identification',
        '',
        f'Training files: {", ".join(sorted({lp.source for lp in train}))}  ',
        f'Held out: {", ".join(sorted({lp.source for lp in hold})) or "none"}  ',
        f'Load sections: {", ".join(_f(v, ".4g") for v in doc["fit"]["sections_MPa"])} MPa '
        f'({", ".join(_f(v, ".4g") for v in doc["fit"]["sections_kgf"])} kgf per 0.25 mm wire)  ',
        f'Identified model: `{doc["params_file"]}`  ',
        f'Load law of the envelopes: {doc["model"]} ({doc["model_selection"]["reason"]}; mean interior '
        f'leave-one-load-out RMS per law: '
        f'{", ".join(f"{k} {v:.2f} %" for k, v in doc["model_selection"]["interior_loo_rms_pct"].items()) or "not run"})',
        '',
        '## Before fitting: the current model against the data',
        '',
        f'Model: {before_model.name}; {doc["before"]["note"]}.',
        '',
        '| file | stress [MPa] | RMS [% stroke] | max [% stroke] | T outside model range [%] | load clipped |',
        '|---|---|---|---|---|---|',
    ]
    for b in doc['before']['per_load']:
        L.append(
            f'| {Path(b["file"]).name} | {b["stress_MPa"]:.4g} | {_f(b["rms_pct"], ".1f")} | {_f(b["max_pct"], ".1f")} '
            f'| {_f(b["clipped_temperature_pct"], ".0f")} | {"yes" if b["load_clipped"] else "no"} |'
        )
    L += [
        '',
        '### Transition temperatures (10/50/90 % of each branch) and stroke',
        '',
        '| stress [MPa] | | A_s | A_50 | A_f | M_s | M_50 | M_f | stroke [mm, 80 mm wire] |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    tr = doc['transitions']
    allp = train + hold
    for i, lp in enumerate(allp):
        for tag, src in (
            ('measured', tr['measured'][i]),
            ('before', tr['before'][i]),
            ('fitted', tr['fitted'][i] if i < len(train) else None),
        ):
            if src is None:
                continue
            L.append(
                f'| {lp.stress_MPa:.4g} | {tag} | '
                + ' | '.join(_f(src[k], '.1f') for k in ('A_s', 'A_50', 'A_f', 'M_s', 'M_50', 'M_f'))
                + f' | {_f(src["stroke_mm"], ".3f")} |'
            )
    L += [
        '',
        'Slopes over stress (Clausius-Clapeyron) [degC/MPa; stroke mm/MPa]:',
        '',
        '| | ' + ' | '.join(('A_s', 'A_50', 'A_f', 'M_s', 'M_50', 'M_f', 'stroke')) + ' |',
        '|---' * 8 + '|',
    ]
    for tag in ('measured', 'before', 'fitted'):
        sl = tr['slopes_per_MPa'][tag]
        L.append(
            f'| {tag} | '
            + ' | '.join(_f(sl[k], '.3g') for k in ('A_s', 'A_50', 'A_f', 'M_s', 'M_50', 'M_f', 'stroke_mm'))
            + ' |'
        )
    L += [
        '',
        '## Fit',
        '',
        '| file | stress [MPa] | samples | cycle | GPI RMS [%] | SD-GPI RMS [%] | SD-GPI max [%] |',
        '|---|---|---|---|---|---|---|',
    ]
    for d in doc['fit']['per_load']:
        L.append(
            f'| {Path(d["file"]).name} | {d["stress_MPa"]:.4g} | {d["samples"]} | {d["cycle"]} of {d["cycles_found"]} '
            f'| {_f(d["gpi_rms_pct"])} | {_f(d["sdgpi_rms_pct"])} | {_f(d["sdgpi_max_pct"])} |'
        )
    L += [
        '',
        f'SD-GPI overall residual: {_f(doc["fit"]["overall_rms_pct"])} % of the mean stroke.',
        '',
        '## Validation on data the fit did not see',
        '',
    ]
    if doc['holdout']:
        L += ['| held-out file | stress [MPa] | RMS [% stroke] | max [% stroke] |', '|---|---|---|---|']
        L += [
            f'| {Path(h["file"]).name} | {h["stress_MPa"]:.4g} | {_f(h["rms_pct"])} | {_f(h["max_pct"])} |'
            for h in doc['holdout']
        ]
    if doc['leave_one_load_out']:
        L += [
            '',
            'Leave-one-load-out (SD-GPI refitted without that stress):',
            '',
            '| stress [MPa] | RMS [% stroke] | max [% stroke] | extrapolated |',
            '|---|---|---|---|',
        ]
        L += [
            f'| {h["stress_MPa"]:.4g} | {_f(h["rms_pct"])} | {_f(h["max_pct"])} | {"yes" if h["extrapolated"] else "no"} |'
            for h in doc['leave_one_load_out']
        ]
    if not doc['holdout'] and not doc['leave_one_load_out']:
        L.append('none requested')
    L += [
        '',
        '## Data cleaning',
        '',
        ('| file | unreadable | NaN | duplicates | unsorted stamps | temperature spikes | load-ramp samples |'),
        '|---|---|---|---|---|---|---|',
    ]
    for f, c in doc['cleaning'].items():
        L.append(
            f'| {Path(f).name} | {c.get("unreadable_rows", 0)} | {c.get("nan_rows", 0)} | {c.get("duplicate_rows", 0)} '
            f'| {c.get("unsorted_stamps", 0)} | {c.get("temperature_spikes", 0)} | {c.get("ramp_samples_dropped", 0)} |'
        )
    if doc['warnings']:
        L += ['', '## Warnings', ''] + [f'- {w}' for w in doc['warnings']]
    L += ['', '## Plots', '']
    L += [f'![{p}]({p})' for p in pngs] if pngs else ['(no plots: matplotlib not installed or --no-plots)']
    p = out / 'report.md'
    p.write_text('\n'.join(L) + '\n')
    return p
