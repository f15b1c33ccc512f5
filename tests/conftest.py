"""Settings for the whole test suite.

``$PREFILTER_DATA`` points at an empty folder for the run (subprocesses inherit it): tests see
the tables shipped with the package, never a user table baked on this machine, and bakes run
without ``-o`` write there, not into the user's data folder.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_DATA = tempfile.mkdtemp(prefix="prefilter-test-data-")


def pytest_configure(config):
    os.environ["PREFILTER_DATA"] = _DATA


def pytest_unconfigure(config):
    shutil.rmtree(_DATA, ignore_errors=True)
