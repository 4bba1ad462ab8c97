"""The package keeps BLAS single-threaded unless the user says otherwise (sma_wrist/__init__.py)."""

import os
import subprocess
import sys


def _threads(env_extra: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if not k.endswith('_NUM_THREADS')}
    env.update(env_extra)
    code = 'import sma_wrist, numpy, os; print(os.environ["OPENBLAS_NUM_THREADS"])'
    return subprocess.run(
        [sys.executable, '-c', code], env=env, capture_output=True, text=True, check=True
    ).stdout.strip()


def test_blas_is_single_threaded_by_default_and_a_user_setting_wins():
    assert _threads({}) == '1'
    assert _threads({'OPENBLAS_NUM_THREADS': '2'}) == '2'
