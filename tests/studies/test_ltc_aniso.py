"""Held-out accuracy of the anisotropic table: configurations, screening and statistics."""

from __future__ import annotations

import numpy as np

from prefilter.ltc import AnisoGGXTable
from prefilter.ltc.aniso.table import shipped_table_path
from prefilter.studies.ltc_aniso import (HELDOUT_SEED, heldout_accuracy, heldout_configurations,
                                         random_aniso_configurations)


def test_heldout_set_is_reproducible_and_screened():
    a = heldout_configurations(60, 4000, screen_samples=400)
    b = heldout_configurations(60, 4000, screen_samples=400)
    np.testing.assert_array_equal(a["ref"], b["ref"])
    # not the acceptance's configurations (seed 0)
    assert not np.allclose(a["wo"], random_aniso_configurations(60, 0)["wo"])
    assert HELDOUT_SEED != 0
    s = heldout_accuracy(AnisoGGXTable.load(shipped_table_path()), a)
    assert s["count"] == int(np.sum(a["ref"] >= 0.05)) and s["of"] == 60 and s["count"] > 5
    assert 0 <= s["median"] <= s["p90"] and s["abs_p90"] >= 0 and s["mc_rel_se"] < 0.05
