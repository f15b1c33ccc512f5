"""Settings for the whole test suite.

``$PREFILTER_DATA`` points at an empty folder for the run (subprocesses inherit it): tests see
the tables shipped with the package, never a user table baked on this machine, and bakes run
without ``-o`` write there, not into the user's data folder.

``$PREFILTER_GLINTS_CACHE`` (unless set) is a folder of the system's temporary directory kept
between runs: glint maps the tests bake (minutes each at the render's settings) are reused by the
next run, and the user's cache is never written.
"""

from __future__ import annotations

import os
import shutil
import tempfile

_DATA = tempfile.mkdtemp(prefix="prefilter-test-data-")


def pytest_configure(config):
    os.environ["PREFILTER_DATA"] = _DATA
    os.environ.setdefault("PREFILTER_GLINTS_CACHE",
                          os.path.join(tempfile.gettempdir(), "prefilter-test-glints"))


def pytest_unconfigure(config):
    shutil.rmtree(_DATA, ignore_errors=True)
