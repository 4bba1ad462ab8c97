"""The documentation's reference is complete and its site builds without a warning.

The reference pages are generated from the sources (doc/refgen.py): every node parameter, contract topic and
``sma-wrist`` command and option must appear with a description, and a number with its unit. The validation page
and the README's results block are rendered from doc/validation/results.json and must show what it holds.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / 'doc'
sys.path.insert(0, str(DOC))

import refgen  # noqa: E402


@pytest.fixture(scope='module')
def pages() -> dict[str, str]:
    return refgen.pages()


@pytest.fixture(scope='module')
def results() -> dict:
    return json.loads(refgen.RESULTS.read_text())


def test_nothing_in_the_reference_lacks_a_description_or_unit() -> None:
    assert refgen.problems() == []


def test_every_node_parameter_has_a_row_on_its_nodes_page(pages) -> None:
    nodes = refgen.nodes()
    assert {n.name for n in nodes} == {p.stem for p in (ROOT / 'sma_wrist' / 'nodes').glob('*.py')} - {
        '__init__',
        'common',
    }
    for n in nodes:
        page = pages[f'reference/nodes/{n.name}.md']
        rows = {line.split(' | ')[0].strip('| `') for line in page.splitlines() if line.startswith('| `')}
        missing = [p.name for p in n.params if p.name not in rows]
        assert not missing, f'{n.name}: parameters without a reference row: {missing}'
        for p in n.params:
            row = next(line for line in page.splitlines() if line.startswith(f'| `{p.name}` |'))
            assert refgen.md(p.description) in row and refgen.ros_type(p.default) in row, row


def test_every_contract_topic_is_on_the_topics_page_and_its_nodes_pages(pages) -> None:
    from sma_wrist.contract import load_contract

    for t in load_contract().topics.values():
        assert f'| `{t.name}` | `{t.type}` |' in pages['reference/topics.md'], t.name
        for node in (t.publisher, t.alt_publisher, *t.subscribers):
            if node and node != '*':
                assert f'| `{t.name}` |' in pages[f'reference/nodes/{node}.md'], (t.name, node)


def test_every_command_and_option_is_on_the_cli_page(pages) -> None:
    page = pages['reference/cli.md']
    cmds = list(refgen.commands())
    assert ('identify', 'hysteresis') in {c.path for c in cmds} and ('identify', 'thermal') in {c.path for c in cmds}
    for c in cmds:
        assert f'`{" ".join(("sma-wrist",) + c.path)}`' in page, c.path
        for a in refgen.options(c.parser):
            assert refgen.code(refgen._option_name(a)) in page, (c.path, a.option_strings or a.dest)


def test_an_undocumented_option_or_unitless_number_is_reported() -> None:
    ap = argparse.ArgumentParser(prog='tool')
    sub = ap.add_subparsers()
    p = sub.add_parser('go', help='does it')
    p.add_argument('--fast', action='store_true')
    p.add_argument('--slow', action='store_true', help='documented')
    sub.add_parser('stop')
    found = refgen.option_problems(list(refgen.commands(ap)))
    assert found == ['sma-wrist go --fast: option without help', 'sma-wrist stop: command without help']

    from sma_wrist.nodes.common import Param

    class Fake:
        PARAMS = (
            Param('gain', 1.0, 'a gain', range=(0.0, 2.0)),
            Param('rate_hz', 1.0, '', 'Hz'),
            Param('count', 3, 'a count'),
        )

    found = refgen.param_problems(refgen.NodeDoc('fake', None, Fake))
    assert found == [
        'fake.gain: a float parameter without unit (use "1" for a ratio)',
        'fake.rate_hz: no description',
        'fake.rate_hz: a float parameter without range',
    ]


def test_markdown_cells_keep_bars_and_markup_literal() -> None:
    assert refgen.md('a|b *c* [d] <e>') == r'a\|b \*c\* \[d\] \<e\>'
    assert refgen.code('x|y') == r'`x\|y`'


def test_the_validation_page_shows_every_measured_figure_and_command(results, pages) -> None:
    page = pages['validation.md']
    for name, run in results['runs'].items():
        assert f'`{run["command"]}`' in page, name
    for name in ('tracking_nominal', 'tracking_off_model'):
        for r in results['runs'][name]['result']:
            assert f'{r["max_error_pct"]:.2f}' in page and f'{r["max_error_pct"]:.1f} %' in page, r
    for s in results['runs']['family']['result']['summary']:
        assert f'{s["median_max_error_pct"]:.2f}' in page
    for h in results['runs']['identify_thermal']['result']['holdout']:
        assert f'{h["rms_C"]:.2f}' in page


def test_the_tracking_table_puts_each_figure_under_its_controller_and_plant(results) -> None:
    table, _ = refgen.tracking_table(results)
    header = [h.strip() for h in table[0].strip('|').split('|')]
    cells = {r.split('|')[1].strip(' `'): [c.strip() for c in r.strip('|').split('|')] for r in table[2:]}
    for r in results['runs']['tracking_off_model']['result']:
        col = header.index(refgen.CASE_TITLES[r['case']])
        assert cells[r['mode']][col] == f'{r["max_error_pct"]:.1f} %'
    for r in results['runs']['tracking_nominal']['result']:
        assert cells[r['mode']][header.index(f'nominal {r["payload_kg"]:g} kg')] == f'{r["max_error_pct"]:.1f} %'


def test_the_readme_results_block_is_the_json(results) -> None:
    readme = (ROOT / 'README.md').read_text()
    assert refgen.README_BEGIN in readme, 'README.md has no results block'
    assert refgen.replace_readme_block(readme, results) == readme, (
        "README.md's results block is not doc/validation/results.json's: run python3 doc/validation/measure.py --readme"
    )


def test_each_validation_row_carries_its_own_start_time(monkeypatch) -> None:
    """measure.py stamped every row with the time the whole ~10 min run started, not when its command ran."""
    import datetime

    sys.path.insert(0, str(DOC / 'validation'))
    import measure

    clock = iter(datetime.datetime(2026, 1, 1, 12, m, tzinfo=datetime.timezone.utc) for m in range(0, 60, 7))

    class Clock(datetime.datetime):
        @classmethod
        def now(cls, tz=None):  # type: ignore[override]
            return next(clock)

    monkeypatch.setattr(measure.datetime, 'datetime', Clock)
    monkeypatch.setattr(measure, 'run_one', lambda name: {'what': name})
    monkeypatch.setattr(measure, '_git', lambda *a: '')
    names = list(measure.RUNS)[:3]
    runs = measure.measure(names)['runs']
    assert [runs[n]['date'] for n in names] == ['2026-01-01 12:00 UTC', '2026-01-01 12:07 UTC', '2026-01-01 12:14 UTC']
    assert all('load_1min_at_start' in runs[n]['machine'] for n in names)


def test_a_readme_without_the_markers_is_refused(results) -> None:
    with pytest.raises(ValueError, match='results:begin'):
        refgen.replace_readme_block('# README\n', results)


@pytest.mark.skipif(
    not all(importlib.util.find_spec(m) for m in ('sphinx', 'myst_parser', 'sphinx_rtd_theme')),
    reason="the docs extra is not installed (pip install '.[docs]')",
)
def test_the_site_builds_without_a_warning(tmp_path) -> None:
    # the dummy builder reads every page and resolves every cross-reference (nitpicky) without writing HTML
    p = subprocess.run(
        [
            sys.executable,
            '-m',
            'sphinx',
            '-W',
            '--keep-going',
            '-q',
            '-b',
            'dummy',
            '-d',
            str(tmp_path / 'doctrees'),
            str(DOC),
            str(tmp_path / 'out'),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert p.returncode == 0, p.stderr[-5000:]
