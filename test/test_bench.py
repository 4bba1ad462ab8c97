"""The benchmark driver's small contracts (the benchmarks themselves are `sma-wrist bench`, not tests)."""

from __future__ import annotations

import os

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


def _figure_section(monkeypatch) -> None:
    """A stand-in section that writes one figure where the real ones do (bench_png)."""
    from sma_wrist import bench

    def fig(quick: bool) -> dict:
        path = bench_png('fig.png')
        open(path, 'w').close()
        return {'png': path}

    monkeypatch.setitem(bench.SECTIONS, 'fig', fig)


def test_figures_go_to_the_benchs_folder_not_the_current_one(tmp_path, monkeypatch):
    """The measured-wire section wrote its PNGs into whatever folder the command was started in."""
    from sma_wrist.bench import run

    _figure_section(monkeypatch)
    monkeypatch.delenv('SMA_WRIST_BENCH_DIR', raising=False)
    monkeypatch.chdir(tmp_path)
    assert run(['fig'])['fig']['png'] == 'runs/bench/fig.png'
    assert [p.name for p in tmp_path.iterdir()] == ['runs']


def test_out_puts_the_figures_there_and_leaves_the_environment_as_it_was(tmp_path, monkeypatch, capsys):
    from sma_wrist.cli import main

    _figure_section(monkeypatch)
    monkeypatch.setenv('SMA_WRIST_BENCH_DIR', str(tmp_path / 'env'))
    assert main(['bench', '--section', 'fig', '--json', '--out', str(tmp_path / 'given')]) == 0
    assert (tmp_path / 'given' / 'fig.png').is_file() and not (tmp_path / 'env').exists()
    assert os.environ['SMA_WRIST_BENCH_DIR'] == str(tmp_path / 'env')
    (tmp_path / 'a_file').write_text('')
    assert main(['bench', '--section', 'fig', '--out', str(tmp_path / 'a_file')]) != 0
    assert '--out' in capsys.readouterr().err
