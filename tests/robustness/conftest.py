"""Shared settings for the robustness tests (issue 10).

Hypothesis profiles: ``ci`` (the default: derandomised, no example database, so every run
generates the same cases on every machine) and ``slow`` (the same with 10x the examples), chosen
with ``PREFILTER_FUZZ=slow``. Property tests take their example budget from the loaded profile
(``settings.default.max_examples``), scaled down for the expensive ones, so the profile scales all.

The terminal summary reports how many cases each property test ran (generated examples, explicit
``@example`` cases and shrinking steps), also under pytest-xdist, where the workers send their
counts to the controller.
"""

from __future__ import annotations

import os
from collections import Counter

import pytest
from hypothesis import HealthCheck, settings

_BASE = dict(
    derandomize=True,
    database=None,
    deadline=None,
    print_blob=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                           HealthCheck.filter_too_much],
)
settings.register_profile("ci", max_examples=30, **_BASE)
settings.register_profile("slow", max_examples=300, **_BASE)
settings.load_profile(os.environ.get("PREFILTER_FUZZ", "ci"))

_COUNTS: Counter = Counter()
_KEY = "prefilter_fuzz_counts"


def _counting(inner, nodeid):
    def run(*args, **kwargs):
        _COUNTS[nodeid] += 1
        return inner(*args, **kwargs)

    return run


def pytest_collection_modifyitems(session, config, items):
    # Hypothesis exposes the undecorated body as `.hypothesis.inner_test` for plugins to wrap.
    for item in items:
        hyp = getattr(getattr(item, "obj", None), "hypothesis", None)
        if hyp is not None and hasattr(hyp, "inner_test") and "robustness" in item.nodeid:
            hyp.inner_test = _counting(hyp.inner_test, item.nodeid)


def pytest_sessionfinish(session, exitstatus):
    out = getattr(session.config, "workeroutput", None)
    if out is not None:  # an xdist worker: hand the counts to the controller
        out[_KEY] = dict(_COUNTS)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    _COUNTS.update(getattr(node, "workeroutput", {}).get(_KEY, {}))


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    if not _COUNTS:
        return
    tr = terminalreporter
    profile = os.environ.get("PREFILTER_FUZZ", "ci")
    tr.section(f"property-based cases (hypothesis profile {profile!r})")
    by_file: Counter = Counter()
    for nodeid, n in sorted(_COUNTS.items()):
        by_file[nodeid.split("::")[0]] += n
        tr.write_line(f"{n:7d}  {nodeid}")
    for path, n in sorted(by_file.items()):
        tr.write_line(f"{n:7d}  total {path}")
    tr.write_line(f"{sum(_COUNTS.values()):7d}  cases in {len(_COUNTS)} property tests")
