"""Residual statistics (whiteness, cross-correlation, lag, binned correlates) and the
markdown + PNG report of a diagnosis."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

LB_DECIMATE = 10  # Ljung-Box on every 10th sample (10 Hz at 100 Hz data)
LB_LAGS = 20
MAX_LAG_S = 3.0


def ljung_box(r: np.ndarray, lags: int = LB_LAGS) -> tuple[float, float]:
    """(Q, p-value) of the Ljung-Box portmanteau test of whiteness."""
    r = np.asarray(r, float) - np.mean(r)
    n = r.size
    if n <= lags + 2 or not np.any(r):
        return 0.0, 1.0
    d = np.dot(r, r)
    acf = np.array([np.dot(r[:-k], r[k:]) / d for k in range(1, lags + 1)])
    q = n * (n + 2) * np.sum(acf**2 / (n - np.arange(1, lags + 1)))
    return float(q), float(stats.chi2.sf(q, lags))


def lag_estimate(meas: np.ndarray, model: np.ndarray, dt: float, max_lag_s: float = MAX_LAG_S) -> float:
    """Delay of the measurement behind the model [s] from the cross-correlation of rates."""
    a = np.diff(meas)
    b = np.diff(model)
    if a.size < 10 or not np.any(b):
        return 0.0
    m = int(max_lag_s / dt)
    a = a - a.mean()
    b = b - b.mean()
    lags = np.arange(-m, m + 1)
    # cc[k] = sum_i a[i + k] b[i] (0 beyond the overlap), all lags at once by FFT: one BLAS dot
    # per lag (601 lags on a 10-minute 100 Hz run) cost ~5 s of CPU in OpenBLAS threading alone
    nf = 1 << (2 * a.size - 2).bit_length()
    full = np.fft.irfft(np.fft.rfft(a, nf) * np.conj(np.fft.rfft(b, nf)), nf)
    cc = np.where(np.abs(lags) < a.size, full[lags % nf], 0.0)
    k = int(np.argmax(cc))
    if 0 < k < cc.size - 1:  # parabolic refinement
        den = cc[k - 1] - 2 * cc[k] + cc[k + 1]
        off = 0.5 * (cc[k - 1] - cc[k + 1]) / den if den else 0.0
    else:
        off = 0.0
    return float((lags[k] + off) * dt)


def correlates(r: np.ndarray, regressors: dict[str, np.ndarray]) -> list[dict[str, float]]:
    """|Pearson r| of the residual with each regressor, strongest first."""
    out = []
    for name, x in regressors.items():
        if x is None or np.std(x) == 0 or np.std(r) == 0:
            continue
        c = float(np.corrcoef(r, x)[0, 1])
        if np.isfinite(c):
            out.append({'regressor': name, 'r': round(c, 3)})
    return sorted(out, key=lambda d: -abs(d['r']))


def binned(r: np.ndarray, x: np.ndarray, bins: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres, mean, std) of r in quantile bins of x."""
    if np.unique(x).size <= 3:
        cs = np.unique(x)
        return cs, np.array([r[x == c].mean() for c in cs]), np.array([r[x == c].std() for c in cs])
    e = np.unique(np.quantile(x, np.linspace(0, 1, bins + 1)))
    i = np.clip(np.searchsorted(e, x, side='right') - 1, 0, e.size - 2)
    cs = 0.5 * (e[:-1] + e[1:])
    m = np.array([r[i == k].mean() if np.any(i == k) else np.nan for k in range(e.size - 1)])
    s = np.array([r[i == k].std() if np.any(i == k) else np.nan for k in range(e.size - 1)])
    return cs, m, s


def channel_stats(
    r: np.ndarray,
    sigma: float,
    regressors: dict[str, np.ndarray],
    meas: np.ndarray,
    model: np.ndarray,
    dt: float,
    valid: np.ndarray | None = None,
) -> dict[str, Any]:
    """Statistics of one channel's residual (1-D; thermal channels are passed per muscle, stacked) over its
    ``valid`` samples (a boolean mask like ``r``; None: all): the samples where the run bridged a gap carry no
    measurement, and counting them as zero residual would understate the RMS by the share of the run bridged."""
    if valid is not None:
        keep = np.asarray(valid, bool)
        if keep.any():
            r = r[keep]
            regressors = {k: np.asarray(v)[keep] for k, v in regressors.items()}
    q, p = ljung_box(r[::LB_DECIMATE])
    rms = float(np.sqrt(np.mean(r**2)))
    return {
        'rms': rms,
        'mean': float(np.mean(r)),
        'noise_sigma': sigma,
        'rms_over_noise': rms / sigma,
        'ljung_box_Q': q,
        'ljung_box_p': p,
        'white': bool(p > 0.01),
        'lag_s': lag_estimate(meas, model, dt),
        'correlates': correlates(r, regressors)[:5],
    }


# ----------------------------------------------------------------------------- report
def drive_replayed(drive: str, differs: int | None) -> str:
    """The report's line on the TEM drive the replays ran on (``drive``: 'applied' or 'commanded'; ``differs``: the
    samples where the applied drive differed from the commands, None where the bag had no commands to compare)."""
    if drive != 'applied':
        return 'replayed the TEM commands (/wrist/tem_{1,2}/command): the bag has no applied drive'
    where = '' if differs is None else f' ({differs} samples where it differed from the command)'
    return f'replayed the applied TEM drive{where}, as the device read it back on /wrist/tem_drive_applied'


def write_report(result: Any, out_dir: str | Path, traces: dict[str, Any]) -> Path:
    """Markdown summary + PNG plots into out_dir; returns the markdown path."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    d = Path(out_dir)
    d.mkdir(parents=True, exist_ok=True)
    t = traces['t']
    pngs = []
    # 1. measured vs model per channel
    chans = [c for c in ('thermal', 'mechanics', 'chain') if c in traces['meas']]
    fig, axes = plt.subplots(2 * len(chans), 1, figsize=(10, 3.2 * 2 * len(chans)), sharex=True, squeeze=False)
    for i, c in enumerate(chans):
        ax, axr = axes[2 * i, 0], axes[2 * i + 1, 0]
        meas, nom, best = traces['meas'][c], traces['nominal'][c], traces['best'][c]
        unit = 'degC' if c == 'thermal' else 'rad'
        ax.plot(t, meas, 'k', lw=0.6, label='measured')
        ax.plot(t, nom, 'C0', lw=0.8, label='nominal')
        ax.plot(t, best, 'C3', lw=0.8, ls='--', label='extended')
        ax.set_ylabel(f'{c} [{unit}]')
        ax.axvline(t[traces['i_train']], color='0.5', ls=':')
        axr.plot(t, meas - nom, 'C0', lw=0.6, label='residual nominal')
        axr.plot(t, meas - best, 'C3', lw=0.6, label='residual extended')
        axr.axvline(t[traces['i_train']], color='0.5', ls=':')
        axr.set_ylabel(f'residual [{unit}]')
        if i == 0:
            ax.legend(loc='upper right', fontsize=7)
            axr.legend(loc='upper right', fontsize=7)
    axes[-1, 0].set_xlabel('t [s] (dotted: end of the fitting part)')
    fig.tight_layout()
    fig.savefig(d / 'replay.png', dpi=90)
    plt.close(fig)
    pngs.append('replay.png')
    # 2. binned nominal residuals vs correlates
    reg = traces['regressors']
    names = [n for n in ('time', 'temperature rate', 'sign joint velocity', 'angle', 'load', 'cycles') if n in reg]
    if names and chans:
        fig, axes = plt.subplots(len(chans), len(names), figsize=(2.6 * len(names), 2.4 * len(chans)), squeeze=False)
        for i, c in enumerate(chans):
            r = traces['meas'][c] - traces['nominal'][c]
            r = r.mean(axis=1) if r.ndim == 2 else r
            for j, n in enumerate(names):
                cs, m, s = binned(r, reg[n])
                ax = axes[i, j]
                ax.errorbar(cs, m, yerr=s, fmt='o-', ms=3, lw=0.8)
                ax.axhline(0, color='0.6', lw=0.5)
                if i == len(chans) - 1:
                    ax.set_xlabel(n, fontsize=8)
                if j == 0:
                    ax.set_ylabel(f'{c} residual', fontsize=8)
                ax.tick_params(labelsize=7)
        fig.tight_layout()
        fig.savefig(d / 'residual_correlates.png', dpi=90)
        plt.close(fig)
        pngs.append('residual_correlates.png')
    # 3. candidate scores
    alts = result.alternatives
    fig, ax = plt.subplots(figsize=(7, 0.3 * len(alts) + 1))
    ax.barh([a['cause'] for a in alts][::-1], [a['score'] for a in alts][::-1], color='C2')
    ax.axvline(0, color='k', lw=0.5)
    ax.set_xlabel('held-out score L (lower is better; nominal = 0)')
    fig.tight_layout()
    fig.savefig(d / 'candidates.png', dpi=90)
    plt.close(fig)
    pngs.append('candidates.png')

    lines = [f'# Model-discrepancy diagnosis: {result.source}', '', f'Model replayed: {result.model}.', '']
    lines.append(f'**{result.summary}**')
    lines.append('')
    if result.warnings:
        lines += ['## Input warnings', ''] + [f'- {w}' for w in result.warnings] + ['']
    lines += [
        '## Result',
        '',
        '| | |',
        '|---|---|',
        f'| discrepancy | {result.discrepancy} |',
        f'| subsystem | {result.subsystem} |',
        f'| cause | {result.cause} |',
        f'| unexplained structure left | {result.unexplained} |',
        f'| held-out RMS before / after ({result.channel}) | {result.rmse_before:.4g} / {result.rmse_after:.4g} |',
        f'| gain | {result.gain_pct:.1f} % (bootstrap 5-95 %: {result.gain_ci[0]:.1f} .. {result.gain_ci[1]:.1f}) |',
        f'| confidence | {result.confidence:.2f} |',
        f'| TEM drive | {drive_replayed(result.drive, result.drive_differs)} |',
        '| TEM exchanger faces started | '
        + {
            'measured': 'at the measured temperatures (/wrist/tem_{1,2}/face_temperature) |',
            'twin': "where the twin's replay had them |",
        }.get(result.thermal_start, 'at rest (no face temperatures recorded) |'),
    ]
    if result.ambiguous_with:
        lines += [
            f'| explain(s) it almost as well | {", ".join(a["cause"] + " (" + a["subsystem"] + ")" for a in result.ambiguous_with)} |',
            f'| measurement that would separate them | {result.separating_measurement} |',
        ]
    for h in result.bound_hits:
        lines.append(f'| on its bound (not a value) | {h["cause"]}: {h["parameter"]} = {h["bound"]:g} |')
    lines.append('')
    if result.parameters:
        lines += [
            '## Fitted parameters',
            '',
            'nominal: the value of the model replayed (an error such as preload_err_mm is 0 there).',
            '',
            '| parameter | value | unit | nominal |',
            '|---|---|---|---|',
        ]
        for k, v in result.parameters.items():
            lines.append(f'| {k} | {v["value"]:.5g} | {v["unit"]} | {v["nominal"]:.5g} |')
        lines.append('')
    lines += [
        '## Per-channel held-out RMS',
        '',
        '| channel | before | after | gain % | 5-95 % |',
        '|---|---|---|---|---|',
    ]
    for c, g in result.channels.items():
        lines.append(
            f'| {c} | {g["rmse_before"]:.4g} | {g["rmse_after"]:.4g} | {g["gain_pct"]:.1f} | '
            f'{g["gain_pct_p05"]:.1f} .. {g["gain_pct_p95"]:.1f} |'
        )
    lines += [
        '',
        '## Residual statistics (whole run after burn-in)',
        '',
        '| channel | model | RMS | RMS / noise | Ljung-Box p | lag [s] | strongest correlates |',
        '|---|---|---|---|---|---|---|',
    ]
    for c, per in result.residual_stats.items():
        for which, s in per.items():
            cor = ', '.join(f'{x["regressor"]} {x["r"]:+.2f}' for x in s['correlates'][:3])
            lines.append(
                f'| {c} | {which} | {s["rms"]:.4g} | {s["rms_over_noise"]:.2f} | {s["ljung_box_p"]:.3g} | '
                f'{s["lag_s"]:.3f} | {cor} |'
            )
    lines += [
        '',
        '## Candidates (ranked)',
        '',
        '| rank | cause | subsystem | score L | main gain % | parameters |',
        '|---|---|---|---|---|---|',
    ]
    for i, a in enumerate(alts, 1):
        ps = ', '.join(f'{k}={v["value"]:.4g} {v["unit"]}' for k, v in a['parameters'].items())
        lines.append(f'| {i} | {a["cause"]} | {a["subsystem"]} | {a["score"]:.3f} | {a["gain_pct"]:.1f} | {ps} |')
    lines += [''] + [f'![{p}]({p})' for p in pngs] + ['']
    if result.params_file:
        lines.append(
            f'Extended model parameters: `{Path(result.params_file).name}` (schema in doc/explanation/diagnosis.md).'
        )
    md = d / 'diagnosis.md'
    md.write_text('\n'.join(lines) + '\n')
    return md
