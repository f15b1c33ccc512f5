"""The demo report's roughness section: baked levels as images, the far-field error table."""

from __future__ import annotations

import re

from prefilter.report.report import Report
from prefilter.report.roughness import roughness_section
from prefilter.roughness.bake import METHODS
from prefilter.studies.roughness import MAPS


def test_roughness_section_images_and_error_table(tmp_path):
    report = Report("t")
    report.add_section("Roughness")
    rows = roughness_section(report, map_size=64, log=lambda s: None)
    assert len(rows) == len(MAPS) * (1 + len(METHODS))
    page = report.write(tmp_path / "r").read_text(encoding="utf-8")
    # three levels per method, each a written PNG
    sources = re.findall(r'<img src="([^"]+)"', page)
    assert len(sources) == 3 * len(METHODS)
    assert all((tmp_path / "r" / s).stat().st_size > 0 for s in sources)
    assert page.count("<tr>") >= len(rows) + 1
    # every method removes most of the plain mip chain's error on the Gaussian map far away
    err = {r["method"]: r["rel_rmse"][6] for r in rows if r["map"] == "gaussian"}
    assert all(err[m] < 0.5 * err["none"] for m in METHODS), err
