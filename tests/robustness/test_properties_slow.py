"""The whole property suite at 10x the examples (hypothesis profile "slow"), for `make test-all`.

Runs ``tests/robustness/test_properties_*.py`` in a subprocess with ``PREFILTER_FUZZ=slow`` (the
profile is chosen when the conftest loads, so it cannot change inside this process).
"""

import os
import pathlib
import subprocess
import sys

import pytest

HERE = pathlib.Path(__file__).resolve().parent


@pytest.mark.slow
def test_property_suite_with_ten_times_the_examples():
    me = pathlib.Path(__file__).name
    files = sorted(str(p) for p in HERE.glob("test_properties_*.py") if p.name != me)
    env = dict(os.environ, PREFILTER_FUZZ="slow")
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-p", "no:xdist", "-m", "not slow", *files],
                          env=env, cwd=HERE.parents[1],
                          capture_output=True, text=True, timeout=1800)
    tail = "\n".join(proc.stdout.splitlines()[-30:])
    assert proc.returncode == 0, tail + proc.stderr[-2000:]
    assert "hypothesis profile 'slow'" in proc.stdout, tail
