"""The commissioning report: ``commission.md`` and PNGs of what each step measured."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np


def _plot(bring: Any, out: Path) -> list[str]:
    """PNGs of the recorded samples: the sensors at rest, the pulses, the angle check (those that ran)."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    t, adc, u = bring.rec.arrays()
    if len(t) < 2:
        return []
    temps, q = bring.physical(adc)
    marks = bring.rec.marks
    files = []
    spans = {
        'pulses': [m for m in marks if m[1].startswith('pulse')],
        'angle': [m for m in marks if m[1].startswith(('heat', 'cool'))],
    }
    for name, ms in spans.items():
        if not ms:
            continue
        t0 = ms[0][0] - bring.lim.rest_s
        t1 = spans['angle'][0][0] if name == 'pulses' and spans['angle'] else t[-1]
        sel = (t >= t0) & (t <= t1)
        if sel.sum() < 2:
            continue
        fig, ax = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
        ax[0].plot(t[sel], u[sel, 0], label='muscle 1 TEM command')
        ax[0].plot(t[sel], u[sel, 1], label='muscle 2 TEM command')
        ax[0].set_ylabel('drive [V]')
        ax[1].plot(t[sel], temps[sel, 0], label='muscle 1')
        ax[1].plot(t[sel], temps[sel, 1], label='muscle 2')
        ax[1].plot(t[sel], temps[sel, 2], '--', label='TEM 1 face')
        ax[1].plot(t[sel], temps[sel, 3], '--', label='TEM 2 face')
        ax[1].set_ylabel('temperature [degC]')
        ax[2].plot(t[sel], q[sel])
        ax[2].set_ylabel('angle [rad]')
        ax[2].set_xlabel('device time [s]')
        for a in ax[:2]:
            a.legend(fontsize=7, loc='upper left')
        for tm, _label in ms:
            for a in ax:
                a.axvline(tm, color='grey', lw=0.5)
        ax[0].set_title(f'{name}: readings through the wiring in use at the end (commands per muscle)')
        fig.tight_layout()
        fname = f'{name}.png'
        fig.savefig(out / fname, dpi=80)
        plt.close(fig)
        files.append(fname)
    return files


def write_report(out: Path, result: dict[str, Any], bring: Any | None) -> Path:
    """``out/commission.md`` (and PNGs): the result, each step's findings, the faults and their fixes."""
    out.mkdir(parents=True, exist_ok=True)
    pngs = _plot(bring, out) if bring is not None else []
    sine_V = (result['steps'].get('excite') or {}).get('sine_V')  # the excitation's sines: the driver rating
    sines = f", the excitation's sines {sine_V:g} V" if sine_V else ''
    lines = [
        '# Wrist commissioning report',
        '',
        f'Status: **{result["status"]}** ({result["device_time_s"]:.1f} s of device time, largest drive sent '
        f'{result["max_drive_V"]:g} V, bring-up limit {result["limits"]["max_drive_V"]:g} V{sines}). '
        f'Device: `{result["port"]}`.',
        '',
    ]
    if result.get('message'):
        lines += [result['message'], '']
    if result['faults']:
        lines += ['## Faults', '', '| kind | channel | what was seen | fix | corrected |', '|---|---|---|---|---|']
        for f in result['faults']:
            lines.append(
                f'| {f["kind"]} | {f["channel"] or "-"} | {f["message"]} | {f["fix"]} | '
                f'{"yes" if f["fixed"] else "no"} |'
            )
        lines.append('')
    if result['warnings']:
        lines += ['## Warnings', ''] + [f'- {w}' for w in result['warnings']] + ['']
    titles = {
        'link': 'Link, sample rate, protocol',
        'sensors': 'Sensors at rest (TEMs 0 V)',
        'tem_pulses': 'TEM pulses: which TEM moves which muscle, and which way',
        'angle': 'Angle: which way each muscle turns the joint',
    }
    for key, title in titles.items():
        lines += [f'## {title}', '']
        step = result['steps'].get(key)
        if step is None:
            lines += ['Not run.', '']
            continue
        if key == 'tem_pulses':
            lines += _pulses(step)
        else:
            lines += _table(step) + ['']
        png = {'tem_pulses': 'pulses.png', 'angle': 'angle.png'}.get(key)
        if png in pngs:
            lines += [f'![{key}]({png})', '']
    lines += _identified(result)
    lines += ['## Parameters', '']
    lines += (
        (
            [f'Written to `{result["params_file"]}`:', '', '```yaml']
            + [f'{k}: {v}' for k, v in result['bridge_params'].items()]
            + ['```', '']
        )
        if result['params_file']
        else ['No params file written (commissioning did not pass).', '']
    )
    path = out / 'commission.md'
    path.write_text('\n'.join(lines))
    return path


def _identified(result: dict[str, Any]) -> list[str]:
    """The excitation's phases and the identified parts with their held-out errors against the built-in model."""
    ex = result['steps'].get('excite')
    if ex is None:
        return []
    out = [
        '## Excitation',
        '',
        f"{ex['device_time_s']:.1f} s of device time, drive up to {ex['max_drive_V']:g} V, muscles kept in the TEMs' "
        f'window {ex["window_C"]} degC (governor active {ex["governed_s"]} s per muscle). Muscles '
        f'{ex["muscle_C"]} degC, angle {ex["angle_rad"]} rad.',
        '',
        '| phase | part | from [s] | to [s] | amplitude [V] | period [s] |',
        '|---|---|---|---|---|---|',
    ]
    for p in ex['phases']:
        out.append(
            f'| {p["label"]} | {p["part"]} | {p["t_start_s"]:.1f} | {p["t_end_s"]:.1f} | {p["amplitude_V"]:g} | '
            f'{p["period_s"] or "-"} |'
        )
    out.append('')
    out += [f'![{f}]({f})' for f in result.get('figures', [])] + ['']
    ident = result.get('identified')
    if not ident:
        return out
    out += [
        '## Identified model',
        '',
        'Each part fitted on the fit phases and predicted on the held-out phases, against the built-in model on the '
        'same data.',
        '',
        '| part | held-out metric | commissioned | built-in | file |',
        '|---|---|---|---|---|',
    ]
    for name, part in ident.items():
        h = part['heldout']
        out.append(
            f'| {name} | {h["metric"]} [{h["unit"]}] | {h["commissioned"]:.4g} | {h["builtin"]:.4g} | '
            f'{part["file"] or "-"} |'
        )
    out.append('')
    for name, part in ident.items():
        out += [f'{name}: ' + _short(part['parameters']), '']
        h = part['heldout']
        if 'phase_fraction' in h:  # every wire candidate's held-out error: the model's wire is chosen by them
            out += [
                f'{name}, every wire candidate held out [{h["unit"]}]: built-in SD-GPI {h["builtin"]:.4g}, shifted '
                f'{h["shift_only"]:.4g}, warped {h["warped"]:.4g}, phase-fraction {h["phase_fraction"]:.4g} (the '
                f"angle's noise {h['angle_noise']:.3g})",
                '',
            ]
        per_tem = part['heldout'].get('per_tem')
        if per_tem:  # each TEM's held-out cycle: the heat balance is handed over only where both are better
            out += [f'{name}, held out per TEM (TEM 1, TEM 2) [{part["heldout"]["unit"]}]: ' + _short(per_tem), '']
    return out


def _pulses(step: dict[str, Any]) -> list[str]:
    """The pulses' temperature changes as a table per run (first, and through the corrected wiring)."""
    out = [
        f'Wiring in use: `{step["wiring_in_use"]}`.',
        '',
        'Change of each reading by the end of a positive pulse on each TEM command [degC]. A wrist wired as '
        'documented warms its own muscle and cools its own TEM face: positive muscle and negative face changes '
        'on the diagonal only.',
        '',
    ]
    for name, title in (
        ('first', 'pulses'),
        ('longer', 'pulses twice as long (a face answered within its noise)'),
        ('verified', 'pulses through the corrected wiring'),
    ):
        p = step.get(name)
        if p is None:
            continue
        out += [
            f'{title} (responses count from {p["response_floor_C"]:g} degC on a muscle, '
            f'{p["face_response_floor_C"]:g} degC on a face; frozen readings: {p["frozen_readings"]}):',
            '',
            '| pulse on | muscle reading 1 | muscle reading 2 | TEM face 1 | TEM face 2 |',
            '|---|---|---|---|---|',
        ]
        for k in range(2):
            m, f = p['muscle_change_C'][k], p['face_change_C'][k]
            out.append(f'| TEM command {k + 1} | {m[0]:+.3f} | {m[1]:+.3f} | {f[0]:+.3f} | {f[1]:+.3f} |')
        out.append('')
    if 'wiring_corrected' in step:
        out += [f'Corrected wiring: `{step["wiring_corrected"]}`.', '']
    return out


def _table(d: dict[str, Any]) -> list[str]:
    rows = ['| item | value |', '|---|---|']
    for k, v in d.items():
        if isinstance(v, dict):
            v = ', '.join(f'{a}: {_short(b)}' for a, b in v.items())
        rows.append(f'| {k} | {_short(v)} |')
    return rows


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f'{v:.4g}'
    if isinstance(v, (list, np.ndarray)):
        return str(v)
    if isinstance(v, dict):
        return ', '.join(f'{a}: {_short(b)}' for a, b in v.items())
    return str(v)


__all__ = ['write_report']
