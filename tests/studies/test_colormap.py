"""The acceptance criteria of colour-map filtering on the plane / sphere scenes (small and full)."""

import numpy as np
import pytest

from prefilter.studies.colormap import CONFIGS, run_acceptance

FAR_LIMIT = {"tabulated": 0.25, "procedural": 0.25, "height": 0.5, "slope": 0.5}


def _check(rows, near_slack=1.05):
    for r in rows:
        if r["distance"] == "far":
            assert r["texels_per_pixel"] >= 32, r
            assert r["lab_ratio"] <= FAR_LIMIT[r["case"]], r
            assert r["flip_ratio"] <= FAR_LIMIT[r["case"]], r
        else:
            assert r["lab_ratio"] <= near_slack, r
            assert r["flip_ratio"] <= near_slack, r


def test_small_far_plane_and_near_sphere():
    # 16 x 16 pixels, 16 x 16 reference samples: the reference's own noise is part of the error
    rows = run_acceptance(16, 16, configs=[CONFIGS[1], CONFIGS[4]])
    assert {r["case"] for r in rows} == set(FAR_LIMIT)
    assert all(np.isfinite(r["lab_filtered"]) for r in rows)
    _check(rows, near_slack=1.1)


@pytest.mark.slow
def test_full_acceptance():
    _check(run_acceptance(48, 32))
