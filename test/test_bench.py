"""The benchmark driver's small contracts (the benchmarks themselves are `sma-wrist bench`, not tests)."""

from __future__ import annotations

import pytest

from sma_wrist.bench import bench_png
from sma_wrist.core.errors import SmaWristError


def test_a_figure_folder_that_does_not_exist_yet_is_made(tmp_path, monkeypatch):
    """A missing $SMA_WRIST_BENCH_DIR ended the measured-wire bench in a traceback after its runs."""
    monkeypatch.setenv('SMA_WRIST_BENCH_DIR', str(tmp_path / 'new' / 'figs'))
    assert bench_png('x.png') == str(tmp_path / 'new' / 'figs' / 'x.png')
    assert (tmp_path / 'new' / 'figs').is_dir()


def test_a_figure_folder_that_cannot_be_made_is_a_clear_error(tmp_path, monkeypatch):
    (tmp_path / 'file').write_text('')
    monkeypatch.setenv('SMA_WRIST_BENCH_DIR', str(tmp_path / 'file'))
    with pytest.raises(SmaWristError, match='SMA_WRIST_BENCH_DIR=.*cannot hold the figures'):
        bench_png('x.png')


def test_an_unknown_section_is_a_clear_error():
    from sma_wrist.bench import run

    with pytest.raises(SmaWristError, match=r"unknown benchmark section\(s\) \['nope'\]"):
        run(['nope'])
