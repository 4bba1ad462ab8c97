"""What a perfect model would give: the closed loops with the plant's own models (a diagnosis).

The inverse mode's median max error over the off-model family of plants is asked to be <= 8 %
(``sma-wrist sweep --plants 40 --seed 1``). This module says where the error that remains
comes from, plant by plant, by giving the loop -- one knowledge gap at a time, then all at
once -- exactly what the plant runs (:func:`sma_wrist.sweep.simulate.simulate`'s ``oracle``):

* ``hysteresis``: the compensator inverts the plant's own SD-GPI (Eqs. 3.19-3.24 with the
  scenario's transition shift and stroke, :func:`~sma_wrist.plants.spread.perturbed_hysteresis`,
  the same :class:`~sma_wrist.core.hysteresis.sdgpi.SDGPIParams` the plant steps), its
  temperature-axis and stroke adaptation off (nothing left to learn);
* ``thermal``: the TEM law (TemLoopBank: observer, Eqs. 5.44-5.47 linearising law, face
  protection) and the compensator's temperature observer integrate the plant's own heat balance
  (Eqs. 4.13-4.15 with the scenario's TEM gain ``input_per_volt``, muscle-face losses K_Tinf,
  K_T, K_inf and ambients, :func:`sma_wrist.core.plant.extensions.plant_params`): every
  perturbation is a field of :class:`~sma_wrist.core.thermal.heat_balance.ThermalParams`, so the
  representation is exact; the command limits stay the law's (driver rating, hold limits);
* ``payload``: the adaptive law knows the payload: theta_hat = the true mass (Eq. 5.33's theta,
  [kg]) with its adaptation off (Gamma_a = 0), and the payload's inertia M l^2 in I (Table 5.4's
  I_w alone otherwise);
* ``sensors``: noise-free, lag-free sensors: the controllers read the plant's true muscle
  temperatures (both consumers of ``true_temperature``, so the compensator bypasses its observer),
  angle and velocity.

The models the law still has its own of: the direct / pid temperature map (force per degC, the
PID gains), the back-stepping law's remaining estimates (beta, D), the reversal lead.

Each oracle needs one model per plant, so every plant runs on its own (the sweep's engine with
one scenario; its modes together): ~1 wrist's Python overhead per tick instead of a share of a
vectorised bank's. ``python -m sma_wrist.plants.oracle`` measures the family and the nominal
plant (doc/explanation/controllers.md).
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sma_wrist.core.errors import ParameterError
from sma_wrist.plants.spread import Scenario, sample

# the loop given the plant's own models: below both this study and the sweep engine that runs it
from sma_wrist.sweep.oracle_models import SWITCHES, check, knows_payload, own_compensator, own_tem_bank  # noqa: F401

#: the variants measured: name -> switches ('as_built': none, the nodes' defaults)
VARIANTS: dict[str, tuple[str, ...]] = {
    'as_built': (),
    'hysteresis': ('hysteresis',),
    'thermal': ('thermal',),
    'payload': ('payload',),
    'sensors': ('sensors',),
    'all': SWITCHES,
    # all but one (the inverse's): what the one gap costs once the others are closed
    'all_but_hysteresis': ('thermal', 'payload', 'sensors'),
    'all_but_thermal': ('hysteresis', 'payload', 'sensors'),
    'all_but_sensors': ('hysteresis', 'thermal', 'payload'),
}
#: the modes run with each variant (the modes without an inverse have no hysteresis model to be given)
VARIANT_MODES: dict[str, tuple[str, ...]] = {
    'as_built': ('inverse_adaptive', 'direct_adaptive', 'pid'),
    'hysteresis': ('inverse_adaptive',),
    'thermal': ('inverse_adaptive', 'direct_adaptive', 'pid'),
    # the inverse loop has no payload model: its compensator takes the desired strain and the measured stress,
    # the adaptive law's forces are not used (test_oracle: the payload oracle leaves it bit-exact)
    'payload': ('direct_adaptive',),
    'sensors': ('inverse_adaptive',),
    'all': ('inverse_adaptive', 'direct_adaptive', 'pid'),
    'all_but_hysteresis': ('inverse_adaptive',),
    'all_but_thermal': ('inverse_adaptive',),
    'all_but_sensors': ('inverse_adaptive',),
}
NOMINAL_PAYLOADS = (0.1, 0.3, 0.6)
LIMIT_PCT, TARGET_PCT = 15.0, 8.0  # the seed's requirement, and the inverse mode's median asked for over the family [%]


# ---------------------------------------------------------------------------------- measurement
def plants(n: int, seed: int, nominal: bool = True) -> list[tuple[str, int, Scenario]]:
    """(group, index, scenario): the sweep's family (payloads as sampled) then the nominal plant's payloads."""
    out = [('spread', i, sc) for i, sc in enumerate(sample(n, seed))]
    if nominal:
        out += [('nominal', i, Scenario(payload_kg=m)) for i, m in enumerate(NOMINAL_PAYLOADS)]
    return out


def _done(path: Path) -> set[tuple[str, int, str]]:
    if not path.exists():
        return set()
    keys = set()
    for line in path.read_text().splitlines():
        try:
            r = json.loads(line)
        except ValueError:  # a line cut by an interrupted run is measured again
            continue
        keys.add((r['group'], r['plant_index'], r['variant']))
    return keys


def measure(
    n: int,
    seed: int,
    variants: Sequence[str],
    out: Path,
    duration_s: float = 126.0,
    nominal: bool = True,
    reach: bool = True,
) -> None:
    """Per plant and variant, the loops' results appended to ``out`` (JSON lines; a rerun skips what is
    there). ``as_built`` runs all plants in one vectorised call (the sweep's figures); the oracles one
    plant at a time. ``reach``: each plant's static reach floor (plants.loop.reach_floor_pct) too."""
    from sma_wrist.plants.loop import OffModelCase, reach_floor_pct
    from sma_wrist.sweep.simulate import Case, simulate

    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise ParameterError(f'unknown variant(s) {", ".join(bad)}; known: {", ".join(VARIANTS)}')
    todo = plants(n, seed, nominal)
    done = _done(out)
    wall = time.perf_counter()
    with out.open('a') as f:

        def put(group: str, i: int, sc: Scenario, variant: str, rows: Iterable[dict[str, Any]]) -> None:
            for r in rows:
                f.write(
                    json.dumps(
                        {
                            'group': group,
                            'plant_index': i,
                            'variant': variant,
                            **sc.to_dict(),
                            'controller': r['controller'],
                            'max_error_pct': r['max_error_pct'],
                            'rms_error_pct': r['rms_error_pct'],
                            'sign_changes_per_s': r['sign_changes_per_s'],
                        }
                    )
                    + '\n'
                )
            f.flush()

        if reach:
            for group, i, sc in todo:
                if (group, i, 'reach') not in done:
                    floor = reach_floor_pct(OffModelCase('sdgpi', sc))
                    f.write(
                        json.dumps({'group': group, 'plant_index': i, 'variant': 'reach', 'reach_floor_pct': floor})
                        + '\n'
                    )
                    f.flush()
            print(f'[oracle] reach floors of {len(todo)} plants ({time.perf_counter() - wall:.0f} s)', file=sys.stderr)
        for variant in variants:
            modes = VARIANT_MODES[variant]
            left = [(g, i, sc) for g, i, sc in todo if (g, i, variant) not in done]
            if variant == 'as_built' and left:
                cases = [
                    Case(k, m, sc, g)
                    for k, (g, i, sc, m) in enumerate((g, i, sc, m) for g, i, sc in left for m in modes)
                ]
                rows, _ = simulate(cases, duration_s)
                for k, (g, i, sc) in enumerate(left):
                    put(g, i, sc, variant, rows[k * len(modes) : (k + 1) * len(modes)])
                print(f'[oracle] as_built: {len(left)} plants ({time.perf_counter() - wall:.0f} s)', file=sys.stderr)
                continue
            for g, i, sc in left:
                rows, _ = simulate(
                    [Case(k, m, sc, g) for k, m in enumerate(modes)], duration_s, oracle=VARIANTS[variant]
                )
                put(g, i, sc, variant, rows)
                print(f'[oracle] {variant}: {g} plant {i} ({time.perf_counter() - wall:.0f} s)', file=sys.stderr)


def load(path: Path) -> list[dict[str, Any]]:
    """The JSON lines of :func:`measure` (one per plant x variant x mode, and one reach row per plant);
    ParameterError naming the line that is not one (e.g. cut by an interrupted run: rerun :func:`measure`)."""
    rows = []
    for k, line in enumerate(Path(path).read_text().splitlines(), 1):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except ValueError as e:
            raise ParameterError(
                f'{path}:{k}: not a JSON row ({e}); an interrupted run? rerun to measure it again'
            ) from None
        if not (isinstance(r, dict) and {'group', 'plant_index', 'variant'} <= set(r)):
            raise ParameterError(f'{path}:{k}: not a row of sma_wrist.plants.oracle (group, plant_index, variant)')
        rows.append(r)
    return rows


def per_plant(rows: Sequence[dict[str, Any]]) -> dict[tuple[str, int], dict[str, Any]]:
    """(group, plant index) -> {'reach_floor_pct', (variant, controller): max error [%], ...}."""
    out: dict[tuple[str, int], dict[str, Any]] = {}
    for r in rows:
        d = out.setdefault((r['group'], r['plant_index']), {})
        if r['variant'] == 'reach':
            d['reach_floor_pct'] = r['reach_floor_pct']
        else:
            d[(r['variant'], r['controller'])] = r['max_error_pct']
            d.setdefault('scenario', {k: r[k] for k in r if k in Scenario.__dataclass_fields__})
    return out


def summary(rows: Sequence[dict[str, Any]], reachable_pct: float = LIMIT_PCT) -> list[dict[str, Any]]:
    """Per (variant, controller): median / share < 15 % / share < 8 % of the max errors over the family's
    plants (all, and those whose reach floor is < ``reachable_pct``), and the nominal plant's errors."""
    pp = per_plant(rows)
    keys = sorted(
        {k for d in pp.values() for k in d if isinstance(k, tuple)},
        key=lambda k: (list(VARIANTS).index(k[0]), ('inverse_adaptive', 'direct_adaptive', 'pid').index(k[1])),
    )
    out = []
    for key in keys:
        fam = [
            (d[key], d.get('reach_floor_pct', np.nan)) for (g, _), d in sorted(pp.items()) if g == 'spread' and key in d
        ]
        if not fam:
            continue
        e = np.array([x for x, _ in fam])
        reach = np.array([x < reachable_pct for _, x in fam])
        nom = [d[key] for (g, _), d in sorted(pp.items()) if g == 'nominal' and key in d]
        row = {
            'variant': key[0],
            'controller': key[1],
            'n': int(e.size),
            'median': float(np.median(e)),
            'under_15': float(np.mean(e < LIMIT_PCT)),
            'under_8': float(np.mean(e < TARGET_PCT)),
            'nominal': nom,
        }
        if reach.any():
            er = e[reach]
            row.update(
                n_reachable=int(er.size),
                median_reachable=float(np.median(er)),
                under_15_reachable=float(np.mean(er < LIMIT_PCT)),
                under_8_reachable=float(np.mean(er < TARGET_PCT)),
            )
        out.append(row)
    return out


def format_summary(summ: Sequence[dict[str, Any]]) -> str:
    """A markdown table of :func:`summary`."""
    lines = [
        '| variant | mode | median % (all) | < 15 % | < 8 % | median % (reachable) | < 15 % | < 8 % | nominal 0.1/0.3/0.6 kg % |',
        '|---|---|---|---|---|---|---|---|---|',
    ]
    for r in summ:
        nom = '/'.join(f'{x:.2f}' for x in r['nominal']) or '-'
        reach = (
            (
                f'{r["median_reachable"]:.2f} (n={r["n_reachable"]}) | {100 * r["under_15_reachable"]:.0f} % | '
                f'{100 * r["under_8_reachable"]:.0f} %'
            )
            if 'n_reachable' in r
            else '- | - | -'
        )
        lines.append(
            f'| {r["variant"]} | {r["controller"]} | {r["median"]:.2f} (n={r["n"]}) | {100 * r["under_15"]:.0f} % | '
            f'{100 * r["under_8"]:.0f} % | {reach} | {nom} |'
        )
    return '\n'.join(lines)


def format_plants(rows: Sequence[dict[str, Any]], controller: str = 'inverse_adaptive') -> str:
    """Per plant: the scenario's axes, reach floor and each variant's max error [%] of ``controller``."""
    pp = per_plant(rows)
    variants = [v for v in VARIANTS if any((v, controller) in d for d in pp.values())]
    head = (
        '| plant | shift degC | stroke | TEM gain | losses | ambient degC | payload kg | floor % | '
        + ' | '.join(variants)
        + ' |'
    )
    lines = [head, '|' + '---|' * (8 + len(variants))]
    for (g, i), d in sorted(pp.items(), key=lambda kv: (kv[0][0] != 'spread', kv[0][1])):
        sc = d.get('scenario', {})
        if not sc:
            continue
        cells = ' | '.join(f'{d[(v, controller)]:.2f}' if (v, controller) in d else '-' for v in variants)
        lines.append(
            f'| {g[:3]} {i} | {sc["transition_shift_C"]:+.1f} | {sc["stroke_scale"]:.2f} | '
            f'{sc["tem_gain_scale"]:.2f} | {sc["heat_loss_scale"]:.2f} | {sc["ambient_offset_C"]:+.1f} | '
            f'{sc["payload_kg"]:.2f} | {d.get("reach_floor_pct", float("nan")):.2f} | {cells} |'
        )
    return '\n'.join(lines)


def plot(rows: Sequence[dict[str, Any]], png: Path) -> None:
    """CDFs of the family's max error per variant: the inverse mode given one model, given all but one, and
    direct_adaptive / pid; the reach floors' CDF (no controller does better); the nominal plant's errors marked."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    pp = per_plant(rows)
    fam = [d for (g, _), d in sorted(pp.items()) if g == 'spread']
    nom = [d for (g, _), d in sorted(pp.items()) if g == 'nominal']
    panels = [
        (
            'inverse_adaptive: one model given',
            ['inverse_adaptive'],
            ['as_built', 'hysteresis', 'thermal', 'sensors', 'all'],
        ),
        (
            'inverse_adaptive: all models but one',
            ['inverse_adaptive'],
            ['as_built', 'all_but_hysteresis', 'all_but_thermal', 'all_but_sensors', 'all'],
        ),
        (
            'direct_adaptive (solid) / pid (dashed)',
            ['direct_adaptive', 'pid'],
            ['as_built', 'thermal', 'payload', 'all'],
        ),
    ]
    fig, axes = plt.subplots(1, len(panels), figsize=(6 * len(panels), 4.8))
    for ax, (title, ctrls, variants) in zip(axes, panels):
        k = 0
        for c in ctrls:
            for v in variants:
                e = np.sort([d[(v, c)] for d in fam if (v, c) in d])
                if not e.size:
                    continue
                label = f'{v}' if len(ctrls) == 1 else f'{c.split("_")[0]} {v}'
                ax.step(
                    np.maximum(e, 1.0),
                    np.arange(1, e.size + 1) / e.size,
                    where='post',
                    color=f'C{k % 10}',
                    ls='--' if c == 'pid' else '-',
                    label=f'{label} (median {np.median(e):.1f} %)',
                )
                ne = [d[(v, c)] for d in nom if (v, c) in d]
                if ne:
                    ax.plot(np.maximum(ne, 1.0), np.full(len(ne), 1.03), 'v', color=f'C{k % 10}', ms=5)
                k += 1
        floors = np.sort([d['reach_floor_pct'] for d in fam if 'reach_floor_pct' in d])
        if floors.size:
            ax.step(
                np.maximum(floors, 1.0),
                np.arange(1, floors.size + 1) / floors.size,
                where='post',
                color='k',
                lw=2.5,
                alpha=0.5,
                label='static reach floor (no controller below)',
            )
        ax.axvline(LIMIT_PCT, color='k', ls='--', lw=1)
        ax.axvline(TARGET_PCT, color='r', ls=':', lw=1, label='8 % (median target)')
        ax.axhline(0.5, color='grey', ls=':', lw=0.8)
        ax.set_xscale('log')
        ax.set_xlim(1.0, 100.0)  # floors of 0 (and errors under 1 %) sit on the left edge
        ax.set_xlabel('max error over the last cycle [% of reference range]')
        ax.set_ylabel("share of the family's plants")
        ax.set_title(f'{title} (nominal plant: triangles)', fontsize=9)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=6.5, loc='lower right')
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)


def _main(
    argv: list[str] | None = None,
) -> None:  # pragma: no cover - the report quoted in doc/explanation/controllers.md
    import argparse

    ap = argparse.ArgumentParser(
        description="the closed loops with the plant's own models (doc/explanation/controllers.md)"
    )
    ap.add_argument('--plants', type=int, default=40)
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--variants', default=','.join(VARIANTS), help=f'comma list of {", ".join(VARIANTS)}')
    ap.add_argument('--duration', type=float, default=126.0)
    ap.add_argument('--no-nominal', action='store_true')
    ap.add_argument('--no-reach', action='store_true')
    ap.add_argument('--out', default='oracle.jsonl', help='JSON lines (appended; a rerun skips what is there)')
    ap.add_argument('--report', action='store_true', help='only the tables and the plot of --out')
    ap.add_argument('--png', default=None, help='the plot (default: --out with .png)')
    a = ap.parse_args(argv)
    out = Path(a.out)
    try:
        if not a.report:
            measure(a.plants, a.seed, a.variants.split(','), out, a.duration, not a.no_nominal, not a.no_reach)
        rows = load(out)
    except (ParameterError, OSError, ValueError, KeyError) as e:
        ap.exit(2, f'oracle: {e}\n')
    print(format_summary(summary(rows)))
    print()
    print(format_plants(rows))
    plot(rows, Path(a.png) if a.png else out.with_suffix('.png'))


if __name__ == '__main__':  # pragma: no cover
    _main()
