"""The far-field roughness study: exact where the baked roughness is exact, and every method
beats the unfiltered mip chain on a Gaussian map."""

from __future__ import annotations

import numpy as np

from prefilter.studies.roughness import (
    far_field_error,
    markdown_table,
    roughness_error_table,
    shade,
)
from prefilter.texture.procedural import normal_map


def test_flat_map_has_no_error():
    n = np.zeros((8, 8, 3))
    n[..., 2] = 1.0
    err = far_field_error(n, 0.09, levels=(1, 3))
    assert max(err.values()) < 1e-12


def test_shade_is_ggx_in_the_normal_frame():
    # a normal tilted by t, light and view mirrored about it: the peak of a flat GGX lobe
    t = 0.3
    n = np.array([np.sin(t), 0.0, np.cos(t)])
    wo = np.array([np.sin(t + 0.2), 0.0, np.cos(t + 0.2)])
    wi = np.array([np.sin(t - 0.2), 0.0, np.cos(t - 0.2)])
    flat_o = np.array([np.sin(0.2), 0.0, np.cos(0.2)])
    flat_i = np.array([-np.sin(0.2), 0.0, np.cos(0.2)])
    assert np.isclose(shade(n[None], np.array([0.1]), wo, wi)[0],
                      shade(np.array([[0.0, 0.0, 1.0]]), np.array([0.1]), flat_o, flat_i)[0])


def test_methods_beat_the_plain_mip_chain_on_a_gaussian_map():
    err = far_field_error(normal_map("gaussian", 64, seed=0), 0.09, levels=(3,))
    for m in ("toksvig", "lean", "ltc"):
        assert err[m, 3] < err["none", 3]


def test_table_rows_and_markdown():
    rows = roughness_error_table(size=16, levels=(1, 2), maps=("flakes",))
    assert [r["method"] for r in rows] == ["none", "toksvig", "lean", "ltc"]
    text = markdown_table(rows)
    assert text.count("\n") == 5 and "level 2 (4x4 texels)" in text
