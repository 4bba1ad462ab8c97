"""Writes the documentation's reference and validation pages from the sources, before Sphinx reads them.

Called by ``doc/conf.py``'s ``setup`` hook (and by ``test/test_docs.py`` without Sphinx). Each page is generated
from the data the code itself runs on, so it cannot drift:

* ``reference/nodes/<node>.md``: every node in ``sma_wrist/nodes`` with its ``Param`` specs (name, ROS type,
  default, unit, range or choices, description) and the topics ``msg_defs/topics.yaml`` gives it;
* ``reference/topics.md``: the interface contract ``msg_defs/topics.yaml``;
* ``reference/cli.md``: every ``sma-wrist`` command, sub-command and option, walked from ``build_parser()``;
* ``reference/api/*.md``: one autodoc page per module of ``sma_wrist.core`` (its docstrings);
* ``validation.md``: the tables of ``validation/results.json`` (written by ``validation/measure.py``).

:func:`problems` lists what is undocumented (an empty description, a float parameter without unit, an option
without help); the test suite fails on any.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import json
import os
import pkgutil
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

DOC = Path(__file__).resolve().parent


def _source_root() -> Path:
    """The package's source tree (package.xml, msg_defs/, sma_wrist/): doc/'s parent, or -- when rosdoc2 builds a
    copy of doc/ in its own folder -- the one of the sma_wrist it puts first on sys.path."""
    if (DOC.parent / 'package.xml').is_file():
        return DOC.parent
    import sma_wrist

    return Path(sma_wrist.__file__).resolve().parent.parent


ROOT = _source_root()
RESULTS = DOC / 'validation' / 'results.json'
#: the pages this module writes (relative to doc/); .gitignore lists them
GENERATED = ('reference/', 'validation.md', 'changelog.md', 'contributing.md')


def version() -> str:
    """The package version from package.xml (the one source colcon and setup.py agree on)."""
    m = re.search(r'<version>([^<]+)</version>', (ROOT / 'package.xml').read_text())
    return m.group(1).strip() if m else 'unknown'


# ----------------------------------------------------------------------------------------------- text helpers

_MD_SPECIAL = re.compile(r'([\\`*_\[\]<>|])')


def md(text: Any) -> str:
    """``text`` as literal Markdown inline text (table cells included)."""
    return _MD_SPECIAL.sub(r'\\\1', ' '.join(str(text).split()))


def code(text: Any) -> str:
    """``text`` as inline code, safe inside a table cell."""
    s = str(text).replace('|', '\\|')
    fence = '``' if '`' in s else '`'
    return f'{fence}{s}{fence}' if s else ''


def _plain_docstring(doc: str | None) -> str:
    """A module docstring's reST markup made Markdown: roles to their target's last name, ``x`` to `x`."""
    if not doc:
        return ''
    text = re.sub(r':\w+:`~?([^`]+)`', lambda m: '`' + m.group(1).split('.')[-1] + '`', doc.strip())
    return text.replace('``', '`')


def _table(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    out += ['| ' + ' | '.join(r) + ' |' for r in rows]
    return out


# ----------------------------------------------------------------------------------------------------- nodes


@dataclass(frozen=True)
class NodeDoc:
    name: str  # the executable / node name, e.g. plant_sim
    module: Any
    cls: Any  # the WristNode subclass

    @property
    def params(self) -> tuple[Any, ...]:
        return tuple(self.cls.PARAMS)


def _activate_runtime() -> None:
    """The embedded rclpy where ROS 2 is absent (node modules import rclpy); a no-op under ROS 2."""
    from sma_wrist import runtime

    runtime.activate()


def nodes() -> list[NodeDoc]:
    """Every node module in sma_wrist/nodes with its WristNode subclass, in file order."""
    _activate_runtime()
    from sma_wrist.nodes.common import WristNode

    out = []
    for f in sorted((ROOT / 'sma_wrist' / 'nodes').glob('*.py')):
        if f.stem in ('__init__', 'common'):
            continue
        mod = importlib.import_module(f'sma_wrist.nodes.{f.stem}')
        classes = [
            c
            for c in vars(mod).values()
            if inspect.isclass(c) and issubclass(c, WristNode) and c is not WristNode and c.__module__ == mod.__name__
        ]
        if len(classes) != 1:
            raise RuntimeError(f'{f}: expected one WristNode subclass, found {[c.__name__ for c in classes]}')
        out.append(NodeDoc(f.stem, mod, classes[0]))
    return out


def ros_type(default: Any) -> str:
    """The ROS parameter type rclpy infers from a default value."""
    if isinstance(default, bool):
        return 'bool'
    if isinstance(default, int):
        return 'integer'
    if isinstance(default, float):
        return 'double'
    if isinstance(default, str):
        return 'string'
    if isinstance(default, (list, tuple)):
        inner = {ros_type(x) for x in default}
        return (inner.pop() if len(inner) == 1 else 'double') + '[]'
    return type(default).__name__


def _default(v: Any) -> str:
    if isinstance(v, bool):
        return code(str(v).lower())
    if isinstance(v, str):
        return code(repr(v)) if v else code("''")
    if isinstance(v, float):
        return code(f'{v:g}')
    return code(v)


def _valid(p: Any) -> str:
    if p.choices:
        return ', '.join(code(c) for c in p.choices)
    if p.range is not None:
        lo, hi = p.range
        return code(f'[{lo:g}, {hi:g}]')
    return ''


def _flags(p: Any) -> str:
    out = []
    if p.read_only:
        out.append('read-only')
    if not p.runtime:
        out.append('at start')
    return ', '.join(out)


def node_page(node: NodeDoc) -> str:
    from sma_wrist.contract import load_contract

    contract = load_contract()
    lines = [
        f'# {node.name}',
        '',
        f'Executable: `ros2 run sma_wrist {node.name}` (class `{node.cls.__module__}.{node.cls.__name__}`).',
        '',
    ]
    lines += [_plain_docstring(node.module.__doc__), '']
    pubs = contract.published_by(node.name)
    subs = [t for t in contract.topics.values() if node.name in t.subscribers]
    lines += ['## Topics', '']
    if pubs or subs:
        rows = [
            [
                code(t.name),
                'publishes' + (' (in some modes)' if t.alt_publisher == node.name else ''),
                code(t.type),
                md(t.unit),
            ]
            for t in pubs
        ]
        rows += [[code(t.name), 'subscribes', code(t.type), md(t.unit)] for t in subs]
        lines += _table(['topic', 'direction', 'type', 'unit'], rows)
    else:
        lines.append('No contract topics besides `/diagnostics`.')
    lines += [
        '',
        'Every node also publishes `/diagnostics`. Topic details: [the interface contract](../topics.md).',
        '',
        '## Parameters',
        '',
        '"at start": read when the node starts; a change at run time is rejected with that reason.',
        '',
    ]
    rows = [
        [code(p.name), ros_type(p.default), _default(p.default), md(p.unit), _valid(p), md(p.description), _flags(p)]
        for p in node.params
    ]
    lines += _table(['name', 'type', 'default', 'unit', 'range / choices', 'description', 'changes'], rows)
    lines += [
        '',
        'A params file that sets every parameter to its default:',
        '',
        '```yaml',
        f'{node.name}:',
        '  ros__parameters:',
    ]
    lines += [f'    {p.name}: {json.dumps(p.default)}' for p in node.params]
    lines += ['```', '']
    return '\n'.join(lines)


# ---------------------------------------------------------------------------------------------------- topics


def topics_page() -> str:
    from sma_wrist.contract import load_contract

    c = load_contract()
    lines = [
        '# Topics',
        '',
        f'The interface contract `msg_defs/topics.yaml` (version {c.version}): the nodes take every name, type '
        'and QoS from it. Frame: ' + code(c.frame_id) + ', joint: ' + code(c.joint_name) + '.',
        '',
    ]
    rows = []
    for t in c.topics.values():
        pub = t.publisher + (f' (or {t.alt_publisher})' if t.alt_publisher else '')
        rate = f'{t.rate_hz:g}' if t.rate_hz else 'on change'
        rows.append(
            [
                code(t.name),
                code(t.type),
                md(t.unit or '-'),
                rate,
                md(t.qos if t.depth == 10 or t.qos != 'reliable' else f'{t.qos}, depth {t.depth}'),
                md(pub),
                md(', '.join(t.subscribers) or '-'),
                md(t.description),
            ]
        )
    lines += _table(['topic', 'type', 'unit', 'rate [Hz]', 'QoS', 'publisher', 'subscribers', 'description'], rows)
    lines.append('')
    return '\n'.join(lines)


# ------------------------------------------------------------------------------------------------------- cli


@dataclass(frozen=True)
class Command:
    path: tuple[str, ...]  # ('identify', 'thermal')
    parser: argparse.ArgumentParser
    help: str


def commands(
    parser: argparse.ArgumentParser | None = None, path: tuple[str, ...] = (), text: str = ''
) -> Iterator[Command]:
    """The parser and every sub-command below it, depth first (``text``: the parser's help line)."""
    if parser is None:
        from sma_wrist.cli import build_parser

        parser = build_parser()
    yield Command(path, parser, text or parser.description or '')
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or '' for a in action._choices_actions}
            for name, sub in action.choices.items():
                yield from commands(sub, path + (name,), helps.get(name, ''))


def options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The documented arguments of one parser (not -h, not the sub-command selector)."""
    return [
        a
        for a in parser._actions
        if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) and a.help != argparse.SUPPRESS
    ]


def _option_help(parser: argparse.ArgumentParser, a: argparse.Action) -> str:
    if not a.help:
        return ''
    try:
        return parser._get_formatter()._expand_help(a)  # %(default)s etc., as --help prints it
    except (KeyError, TypeError, ValueError):
        return a.help


def _option_name(a: argparse.Action) -> str:
    if not a.option_strings:
        return a.metavar if isinstance(a.metavar, str) else a.dest
    meta = ''
    if a.nargs != 0:
        meta = ' ' + (a.metavar if isinstance(a.metavar, str) else a.dest.upper())
    return ', '.join(a.option_strings) + meta


def _option_default(a: argparse.Action) -> str:
    if a.nargs == 0 or a.default in (None, argparse.SUPPRESS) or a.required:
        return ''
    if isinstance(a.default, (list, tuple)):
        return code(','.join(str(x) for x in a.default))
    return code(f'{a.default:g}' if isinstance(a.default, float) else a.default)


def _anchor(path: tuple[str, ...]) -> str:
    return 'cli-' + '-'.join(path or ('sma-wrist',))


def cli_page() -> str:
    lines = [
        '# Command line: `sma-wrist`',
        '',
        'Every command and option, generated from the argument parser the program runs '
        '(`sma_wrist/cli.py`, `build_parser()`); `sma-wrist COMMAND --help` prints the same. Bad input ends '
        'with `error: ...` and exit code 2.',
        '',
    ]
    old = os.environ.get('COLUMNS')
    os.environ['COLUMNS'] = '100'  # argparse wraps usage lines at the terminal width: make the page reproducible
    try:
        for c in commands():
            title = ' '.join(('sma-wrist',) + c.path)
            level = '#' * min(2 + max(len(c.path) - 1, 0), 4)
            lines += [
                f'({_anchor(c.path)})=',
                f'{level} `{title}`',
                '',
                md(c.help),
                '',
                '```text',
                c.parser.format_usage().strip(),
                '```',
                '',
            ]
            subs = [a for a in c.parser._actions if isinstance(a, argparse._SubParsersAction)]
            for s in subs:
                helps = {a.dest: a.help or '' for a in s._choices_actions}
                rows = [[f'[`{name}`](#{_anchor(c.path + (name,))})', md(helps.get(name, ''))] for name in s.choices]
                lines += _table(['command', 'what it does'], rows) + ['']
            opts = options(c.parser)
            if opts:
                rows = []
                for a in opts:
                    choices = ', '.join(code(x) for x in a.choices) if a.choices else ''
                    rows.append(
                        [
                            code(_option_name(a)),
                            _option_default(a),
                            choices,
                            md(_option_help(c.parser, a)) + (' (required)' if a.required and a.option_strings else ''),
                        ]
                    )
                lines += _table(['argument', 'default', 'choices', 'description'], rows) + ['']
    finally:
        if old is None:
            os.environ.pop('COLUMNS', None)
        else:
            os.environ['COLUMNS'] = old
    return '\n'.join(lines)


# ------------------------------------------------------------------------------------------------------- api


def core_modules() -> list[str]:
    """Every module of sma_wrist.core (the package and its sub-packages included), sorted."""
    import sma_wrist.core as core

    names = ['sma_wrist.core'] + [m.name for m in pkgutil.walk_packages(core.__path__, 'sma_wrist.core.')]
    return sorted(names)


def api_page(module: str) -> str:
    return '\n'.join([f'# `{module}`', '', '```{eval-rst}', f'.. automodule:: {module}', '```', ''])


def api_index(modules: list[str]) -> str:
    lines = [
        '# Python API: `sma_wrist.core`',
        '',
        'The numerical core, from its docstrings (numpy style: parameters with units, equation numbers of the '
        'dissertation). Nothing here imports ROS.',
        '',
        '```{toctree}',
        ':maxdepth: 1',
        '',
    ]
    lines += [m for m in modules]
    lines += ['```', '']
    return '\n'.join(lines)


# ------------------------------------------------------------------------------------------------ validation


def validation_page(results: dict[str, Any] | None = None) -> str:
    """The validation page from results.json (see doc/validation/measure.py)."""
    if results is None:
        results = json.loads(RESULTS.read_text()) if RESULTS.exists() else None
    return render_validation(results)


# ----------------------------------------------------------------------------------------------------- write


def _include(name: str, *options: str, title: str = '') -> str:
    """A page that includes the top-level file ``name`` (CHANGELOG.rst, CONTRIBUTING.md), by its path from doc/:
    rosdoc2 builds a copy of doc/ away from the sources, where a typed ``../`` would miss."""
    path = os.path.relpath(ROOT / name, DOC)
    return '\n'.join(([f'# {title}', ''] if title else []) + [f'```{{include}} {path}', *options, '```', ''])


def pages() -> dict[str, str]:
    """Every generated page: path relative to doc/ -> Markdown text."""
    out: dict[str, str] = {
        # CHANGELOG.rst's own title (3 lines and a blank) gives way to the page's
        'changelog.md': _include('CHANGELOG.rst', ':parser: rst', ':start-line: 4', title='Changelog'),
        'contributing.md': _include('CONTRIBUTING.md'),  # its own heading is the page's title
    }
    node_list = nodes()
    out['reference/nodes/index.md'] = '\n'.join(
        [
            '# Nodes',
            '',
            'Every node of the package with its parameters and topics, generated from the parameter specs '
            '(`PARAMS`) the node declares and from `msg_defs/topics.yaml`.',
            '',
            '```{toctree}',
            ':maxdepth: 1',
            '',
        ]
        + [n.name for n in node_list]
        + ['```', '']
    )
    for n in node_list:
        out[f'reference/nodes/{n.name}.md'] = node_page(n)
    out['reference/topics.md'] = topics_page()
    out['reference/cli.md'] = cli_page()
    mods = core_modules()
    out['reference/api/index.md'] = api_index(mods)
    for m in mods:
        out[f'reference/api/{m}.md'] = api_page(m)
    out['validation.md'] = validation_page()
    return out


def write_pages(srcdir: Path | None = None) -> list[Path]:
    """Write every generated page under ``srcdir`` (default: doc/, the folder of this file, also in rosdoc2's copy);
    a page whose text is unchanged is not touched, so Sphinx rebuilds only what changed."""
    base = Path(srcdir) if srcdir else DOC
    written = []
    for rel, text in pages().items():
        p = base / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        if not p.exists() or p.read_text() != text:
            p.write_text(text)
        written.append(p)
    return written


# ---------------------------------------------------------------------------------------------------- checks


def param_problems(node: NodeDoc) -> list[str]:
    """What a node's parameter reference would lack: a description, a unit or range for a number."""
    out = []
    for p in node.params:
        where = f'{node.name}.{p.name}'
        if not p.description.strip():
            out.append(f'{where}: no description')
        if isinstance(p.default, float) and not isinstance(p.default, bool):
            if not p.unit.strip():
                out.append(f'{where}: a float parameter without unit (use "1" for a ratio)')
            if p.range is None:
                out.append(f'{where}: a float parameter without range')
    return out


def option_problems(cmds: list[Command] | None = None) -> list[str]:
    """Commands and options without a help text."""
    out = []
    for c in commands() if cmds is None else cmds:
        name = ' '.join(('sma-wrist',) + c.path)
        if c.path and not c.help.strip():
            out.append(f'{name}: command without help')
        for a in options(c.parser):
            if not _option_help(c.parser, a).strip():
                out.append(f'{name} {_option_name(a)}: option without help')
    return out


def topic_problems() -> list[str]:
    from sma_wrist.contract import load_contract

    out = []
    for t in load_contract().topics.values():
        if not t.description.strip():
            out.append(f'{t.name}: no description')
        if '/msg/' not in t.type:
            out.append(f'{t.name}: type {t.type!r} is not package/msg/Name')
    return out


def problems() -> list[str]:
    """Everything the reference would leave undocumented; empty when complete."""
    out = []
    for n in nodes():
        out += param_problems(n)
    return out + topic_problems() + option_problems()


# ------------------------------------------------------------------------------------------ validation render

README_BEGIN = '<!-- results:begin -->'
README_END = '<!-- results:end -->'
MODES = ('inverse_adaptive', 'direct_adaptive', 'pid')
#: sma_wrist.plants.loop case -> column title
CASE_TITLES = {
    'sensors': 'noisy sensors',
    'T-10': 'transitions -10 degC',
    'T+5': 'transitions +5 degC',
    'stroke x1.3': 'stroke x1.3',
    'TEM gain -30%': 'TEM gain -30 %',
    'phase_fraction': 'phase-fraction wrist',
}


def _run(results: dict[str, Any], name: str) -> dict[str, Any] | None:
    return (results.get('runs') or {}).get(name)


def _pct(v: float | None, digits: int = 1) -> str:
    return 'n/a' if v is None else f'{v:.{digits}f} %'


def tracking_table(results: dict[str, Any]) -> tuple[list[str], list[str]]:
    """(Markdown table lines, the commands behind its columns): max tracking error over the last 62.8 s cycle
    [% of the reference's range] per controller, the nominal plant beside the off-model ones."""
    nominal, off = _run(results, 'tracking_nominal'), _run(results, 'tracking_off_model')
    wire, family = _run(results, 'measured_wire'), _run(results, 'family')
    loads = sorted({r['payload_kg'] for r in nominal['result']}) if nominal else []
    cases = list(dict.fromkeys(r['case'] for r in off['result'])) if off else []
    header = ['controller'] + [f'nominal {m:g} kg' for m in loads] + [CASE_TITLES.get(c, c) for c in cases]
    if wire:
        header.append('measured Flexinol wire')
    if family:
        header.append('40 sampled plants: median (share < 15 %)')
    rows = []
    for mode in MODES:
        row = [code(mode)]
        for m in loads:
            row += [
                _pct(
                    next(
                        (r['max_error_pct'] for r in nominal['result'] if r['mode'] == mode and r['payload_kg'] == m),
                        None,
                    )
                )
            ]
        for c in cases:
            row += [
                _pct(next((r['max_error_pct'] for r in off['result'] if r['mode'] == mode and r['case'] == c), None))
            ]
        if wire:
            row += [
                _pct(
                    next(
                        (
                            r['max_error_pct']
                            for r in wire['result']['runs']
                            if r['controller'] == mode and 'without' not in r['case']
                        ),
                        None,
                    )
                )
            ]
        if family:
            s = next(
                (s for s in family['result']['summary'] if s['group'] == 'spread' and s['controller'] == mode), None
            )
            row += [f'{_pct(s["median_max_error_pct"])} ({100 * s["share_under_15_pct"]:.0f} %)' if s else 'n/a']
        rows.append(row)
    cmds = [r['command'] for r in (nominal, off, wire, family) if r]
    return _table(header, rows), cmds


def _stamp(results: dict[str, Any]) -> str:
    runs = list((results.get('runs') or {}).values())
    dates = sorted({r['date'][:10] for r in runs})
    commits = sorted({r['commit'] + ('+' if r.get('dirty') else '') for r in runs})
    cpus = sorted({f'{r["machine"]["cpu"]} ({r["machine"]["cpu_count"]} CPUs)' for r in runs})
    return f'measured {", ".join(dates)} at commit {", ".join(code(c) for c in commits)} on {"; ".join(cpus)}'


def render_validation(results: dict[str, Any] | None) -> str:
    """The validation page's Markdown from results.json (None: a page saying how to measure)."""
    lines = [
        '# Validation',
        '',
        'Every figure on this page is read from `doc/validation/results.json`, which '
        '`python3 doc/validation/measure.py` writes by running the commands shown; the page is rendered from it '
        'at each docs build. `python3 doc/validation/measure.py --only NAME` repeats one row.',
        '',
    ]
    if not results or not results.get('runs'):
        return '\n'.join(lines + ['No results yet: run `python3 doc/validation/measure.py`.', ''])
    stamp = _stamp(results)
    lines += [
        stamp[0].upper() + stamp[1:] + ". The figures are this machine's at that commit: `measure.py` gives yours.",
        '',
    ]
    table, cmds = tracking_table(results)
    lines += [
        '## Tracking: the nominal plant and plants that are not the model',
        '',
        'Max tracking error over the last full 62.8 s cycle of the Sec. 6.1 sine (126 s), in % of the '
        "reference's range, the sine from its first value (trajectory_generator's `soft_start_s` 0, its default; "
        "`sma-wrist run` starts it at the wrist's angle unless given `--soft-start 0`). The named off-model plants "
        'and the nominal one run on the sweep engine, which '
        'equals the node graph to the last bit; the measured wire runs in the node graph; the 40 plants '
        'are sampled around the nominal one (`sma-wrist sweep`).',
        '',
    ]
    lines += table + ['', 'Reproduce:', '']
    lines += [f'- `{c}`' for c in cmds] + ['']
    lines += _tracking_details(results) + _family(results) + _identification(results) + _thermal_rows(results)
    lines += ['## How each row was measured', '']
    rows = [
        [
            code(k),
            md(r['what']),
            code(r['command']),
            f'{r["wall_s"]:.0f}',
            f'{r["cpu_s"]:.0f}',
            md(r['date']),
            code(r['commit'] + ('+' if r.get('dirty') else '')),
        ]
        for k, r in results['runs'].items()
    ]
    lines += _table(['name (`--only`)', 'what', 'command', 'wall [s]', 'CPU [s]', 'date', 'commit'], rows) + ['']
    m = next(iter(results['runs'].values()))['machine']
    lines += [f'Machine: {md(m["cpu"])}, {m["cpu_count"]} CPUs, {md(m["system"])}, Python {md(m["python"])}.', '']
    return '\n'.join(lines)


def _tracking_details(results: dict[str, Any]) -> list[str]:
    rows = []
    for name in ('tracking_nominal', 'tracking_off_model'):
        r = _run(results, name)
        for x in r['result'] if r else []:
            rows.append(
                [
                    md(CASE_TITLES.get(x['case'], x['case'])),
                    f'{x["payload_kg"]:g}',
                    code(x['mode']),
                    f'{x["max_error_pct"]:.2f}',
                    f'{x["rms_error_pct"]:.2f}',
                    f'{x["reversals_per_s"]:.2f}',
                ]
            )
    w = _run(results, 'measured_wire')
    for x in w['result']['runs'] if w else []:
        rows.append(
            [
                md(x['case']),
                '0.3',
                code(x['controller']),
                f'{x["max_error_pct"]:.2f}',
                f'{x["rms_error_pct"]:.2f}',
                'n/a',
            ]
        )
    if not rows:
        return []
    out = [
        '### Every loop',
        '',
        'Max and RMS error over the last cycle, and the TEM command reversals per second (chattering; the worse TEM).',
        '',
    ]
    out += _table(['plant', 'payload [kg]', 'controller', 'max [%]', 'RMS [%]', 'reversals [1/s]'], rows) + ['']
    if w:
        out += [
            f'The measured wire runs with the pre-load `identify` calibrated for it '
            f'({w["result"]["preload_elongation_mm"]:.2f} mm) and its temperature window '
            f'{w["result"]["window_C"][0]:.0f}-{w["result"]["window_C"][1]:.0f} degC.',
            '',
        ]
    return out


def _family(results: dict[str, Any]) -> list[str]:
    f = _run(results, 'family')
    if not f:
        return []
    rows = [
        [
            md(s['group']),
            code(s['controller']),
            str(s['loops']),
            f'{s["median_max_error_pct"]:.2f}',
            f'{s["p95_max_error_pct"]:.2f}',
            f'{100 * s["share_under_15_pct"]:.0f}',
        ]
        for s in f['result']['summary']
    ]
    return (
        [
            '## Over a sampled family of off-model plants',
            '',
            f'`{f["command"]}`: {f["result"]["loops"]} closed loops; "spread" are the sampled plants, "nominal" '
            'the model itself at the same payloads.',
            '',
        ]
        + _table(['plants', 'controller', 'loops', 'median max [%]', 'p95 max [%]', 'under 15 % [%]'], rows)
        + ['']
    )


def _identification(results: dict[str, Any]) -> list[str]:
    rows = []
    for name, r in (results.get('runs') or {}).items():
        if not name.startswith('identify_') or name == 'identify_thermal':
            continue
        x = r['result']
        loads = ', '.join(f'{p["stress_MPa"]:.0f}' for p in x['per_load'])
        held = '; '.join(f'{h["stress_MPa"]:.0f} MPa: {h["rms_pct"]:.2f} / {h["max_pct"]:.1f}' for h in x['holdout'])
        before = x['before_rms_pct']
        rows.append(
            [
                md(r['what'].split(' (')[0]),
                loads,
                md(x['model']),
                f'{x["in_sample_rms_pct"]:.2f}',
                held or 'none (in-sample only)',
                f'{min(before):.1f}-{max(before):.1f}',
                code(r['command']),
            ]
        )
    if not rows:
        return []
    return (
        [
            '## Identification on measured wires',
            '',
            "SD-GPI fitted by `sma-wrist identify hysteresis` (errors in % of each loop's stroke): RMS over the "
            "fitted loops, RMS / max on a load it never saw, and the built-in parameter set's RMS on the fitted "
            'loops for comparison.',
            '',
        ]
        + _table(
            [
                'wire',
                'fitted loads [MPa]',
                'load law',
                'fitted RMS [%]',
                'held out: RMS / max [%]',
                'built-in set RMS [%]',
                'command',
            ],
            rows,
        )
        + ['']
    )


def _thermal_rows(results: dict[str, Any]) -> list[str]:
    t = _run(results, 'identify_thermal')
    if not t:
        return []
    rows = [
        [md(h['record']), f'{h["rms_C"]:.2f}', 'n/a' if h['table_4_9_rms_C'] is None else f'{h["table_4_9_rms_C"]:.2f}']
        for h in t['result']['holdout']
    ]
    out = [
        '## A real Peltier module',
        '',
        'The heat balance fitted by `sma-wrist identify thermal` on one logged run of a Peltier-heated chamber '
        "(`test/data/tec_chamber`) predicts the module's other runs: RMS of the chamber temperature on runs "
        "it never saw, beside the dissertation's Table 4.9 parameters on the same samples. The logs' PWM duty "
        'is converted to the mean drive voltage first (duty / 255 x 5 V; `measure.py --only identify_thermal` '
        'writes the converted tables, then runs:)',
        '',
        f'`{t["command"]}`',
        '',
    ]
    out += _table(['held-out run', 'fitted model RMS [degC]', 'Table 4.9 RMS [degC]'], rows) + ['']
    if t['result']['warnings']:
        out += ['What the fit says it cannot determine:', ''] + [f'- {md(w)}' for w in t['result']['warnings']] + ['']
    return out


def readme_block(results: dict[str, Any]) -> str:
    """The README's results block: the tracking table, its stamp and where it comes from."""
    table, cmds = tracking_table(results)
    return '\n'.join(
        [
            README_BEGIN,
            '<!-- generated by python3 doc/validation/measure.py --readme; do not edit -->',
            "Max tracking error, Sec. 6.1 sine from its first value (the nodes' default; `sma-wrist run` "
            "starts it at the wrist's angle, `--soft-start 0` runs it so), last cycle of 126 s, % of the reference "
            f"range ({_stamp(results)}; every figure and its command: the docs' Validation page):",
            '',
        ]
        + table
        + ['', README_END]
    )


def replace_readme_block(text: str, results: dict[str, Any]) -> str:
    """``text`` (README.md) with its results block rendered from ``results``; ValueError without the markers."""
    i, j = text.find(README_BEGIN), text.find(README_END)
    if i < 0 or j < i:
        raise ValueError(f'README.md has no {README_BEGIN} ... {README_END} block')
    return text[:i] + readme_block(results) + text[j + len(README_END) :]
