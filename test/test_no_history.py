"""The shipped text speaks to users: no development history in README, CHANGELOG, doc/ or the package.

Docs, messages, comments, docstrings and test names say what the package does and why (a decision with its
measured reason); they do not name work sessions, tracker numbers, internal branch names or dated diary
entries. The patterns are assembled from pieces so that this file does not match itself.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ('README.md', 'CHANGELOG.rst', 'doc', 'sma_wrist', 'test', 'config', 'launch', 'msg_defs')
TEXT_SUFFIXES = {'.py', '.md', '.rst', '.yaml', '.yml', '.txt', '.xml', '.cfg', '.toml', '.json'}
SKIP_PARTS = {'__pycache__', '_build'}
THIRD_PARTY = ROOT / 'test' / 'data'  # published data sets, kept unchanged with their own READMEs

S, I, N = 'sess' + 'ion', 'iss' + 'ue', r'\d+'
#: name -> pattern (case-insensitive); each is a kind of history a user has no use for
PATTERNS = {
    'work session': rf'\b{S}s?\s+{N}\b|\b{S}\s+{N}\'s\b',
    'tracker number': rf'\b{I}s?\s*#?{N}\b|(?<![\w&/#])(?<!Nitinol )#{N}\b(?![.\d])',
    'branch or worker name': r'\b(?:ctrl|pid|oracle|direct)1[0-9][a-z]?\b|(?<=\s)\(le'
    + r'ad[,)]|\ble'
    + r"ad's table\b",
    'helper': r'\banother hel' + r'per\b|\bhel' + r"per's\b",
    'other person': r'\banother eng' + r'ineer\b',
    'dated diary entry': r'\b(?:until|since|before|after|as of)\s+20\d\d-[01]\d-[0-3]\d\b|^#+ .*\(.*20\d\d-[01]\d-[0-3]\d.*\)\s*$',
}
COMPILED = {name: re.compile(p, re.IGNORECASE | re.MULTILINE) for name, p in PATTERNS.items()}


def shipped_files() -> list[Path]:
    out = []
    for entry in SHIPPED:
        p = ROOT / entry
        files = [p] if p.is_file() else sorted(p.rglob('*')) if p.is_dir() else []
        out += [
            f
            for f in files
            if f.is_file()
            and f.suffix in TEXT_SUFFIXES
            and not SKIP_PARTS.intersection(f.relative_to(ROOT).parts)
            and THIRD_PARTY not in f.parents
        ]
    return out


def history_hits(text: str) -> list[tuple[str, str]]:
    """(pattern name, the matching line) for every history mention in ``text``."""
    hits = []
    for name, rx in COMPILED.items():
        for m in rx.finditer(text):
            start = text.rfind('\n', 0, m.start()) + 1
            end = text.find('\n', m.end())
            hits.append((name, text[start : end if end >= 0 else None].strip()))
    return hits


@pytest.mark.parametrize(
    'sample, kind',
    [
        (f'measured in {S} 12 on the loaded machine', 'work session'),
        (f'fixed for {I} 14 item 2', 'tracker number'),
        (f'see #{14}', 'tracker number'),
        (f'## The pair gates the shift ({"le" + "ad"}, 2026-11-24)', 'branch or worker name'),
        ('the pre-load (' + 'ctrl' + '14e)', 'branch or worker name'),
        ('measured by ' + 'pid' + '14b', 'branch or worker name'),
        ('Un' + 'til 2026-11-25 the bridge had neither', 'dated diary entry'),
        ('## Real ROS 2 Jazzy (checked 2026-11-28)', 'dated diary entry'),
        ('added in parallel by ' + 'another eng' + 'ineer', 'other person'),
    ],
)
def test_each_pattern_catches_its_kind(sample: str, kind: str) -> None:
    assert kind in [name for name, _ in history_hits(sample)]


@pytest.mark.parametrize(
    'sample',
    [
        'the reversal lead (reversal_lead_s 2.75 s) starts the crossing early',
        'a helper from another file, the small helpers the kernels call',
        'a pytest fixture with scope=session',
        'colour #1f77b4, a YAML comment # 2 V, item 3 of the list, Nitinol #6 wire',
        'rows = _sine_run(lead)',
        'a logger clock stamp such as 2024-05-01 13:45:07.5',
        'CRC-16 check value of 123456789 is 29B1',
    ],
)
def test_ordinary_words_are_not_history(sample: str) -> None:
    assert history_hits(sample) == []


def test_the_shipped_files_carry_no_development_history() -> None:
    files = shipped_files()
    assert any(f.name == 'README.md' for f in files) and any(f.suffix == '.py' for f in files)
    found = [
        f'{f.relative_to(ROOT)}: {kind}: {line[:160]}'
        for f in files
        for kind, line in history_hits(f.read_text(encoding='utf-8', errors='replace'))
    ]
    assert not found, 'development history in shipped files:\n' + '\n'.join(found)
