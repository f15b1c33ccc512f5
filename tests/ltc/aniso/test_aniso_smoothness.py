"""Smoothness of shaded values along continuous sweeps, and why alignment exists (paper sec. 5)."""

import numpy as np
import pytest

from prefilter.ltc.aniso.align import align, rotation_z
from prefilter.ltc.aniso.table import AnisoGGXTable


def view(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


N = 1501


def quad_toward(d, size=0.35):
    """A square light of half-size ``size`` at distance 1 in direction ``d``, facing the origin."""
    d = d / np.linalg.norm(d)
    a = np.cross(d, [0.0, 0.0, 1.0] if abs(d[2]) < 0.9 else [1.0, 0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(d, a)
    q = np.array([d - size * a - size * b, d - size * a + size * b, d + size * a + size * b,
                  d + size * a - size * b])
    q[:, 2] = np.maximum(q[:, 2], 0.02)  # keep the light above the horizon
    return q


def jumps(values):
    """Indices where a step is more than twice both neighbouring steps (and not noise-sized).

    A kink (interpolation across a grid node) changes the slope but each step stays between its
    neighbours; only a discontinuity makes one step stand out from both.
    """
    d = np.abs(np.diff(values))
    tol = 0.05 * (values.max() - values.min()) / len(values)
    big = (d[1:-1] > 2 * np.maximum(d[:-2], d[2:])) & (d[1:-1] > tol)
    return np.flatnonzero(big) + 1


def sweeps():
    """(name, wo (N, 3), alpha_x (N,), alpha_y (N,), quad) for azimuth, view angle, roughness."""
    s = np.linspace(0, 1, N)
    phi = np.radians(-180 + 360 * s)
    t = np.radians(55)
    wo_phi = np.stack([np.sin(t) * np.cos(phi), np.sin(t) * np.sin(phi),
                       np.full(N, np.cos(t))], -1)
    th = np.radians(85 * s)
    p = np.radians(35)
    wo_th = np.stack([np.sin(th) * np.cos(p), np.sin(th) * np.sin(p), np.cos(th)], -1)
    wo_a = np.broadcast_to(view(50, 30), (N, 3))
    one = np.ones(N)
    return [
        ("azimuth", wo_phi, 0.35 * one, 0.12 * one, quad_toward(np.array([0.3, 0.5, 0.8]))),
        ("view angle", wo_th, 0.4 * one, 0.1 * one, quad_toward(np.array([-0.5, -0.3, 0.6]))),
        ("roughness", wo_a, 0.3 * one, 0.05 + 0.75 * s, quad_toward(-view(50, 30) * [1, 1, -1])),
    ]


@pytest.mark.parametrize("k", range(3))
def test_shading_sweeps_are_continuous(table, k):
    name, wo, ax, ay, quad = sweeps()[k]
    v = table.shade(wo, ax, ay, quad)
    assert v.max() > 1e-3, name  # the light is lit by the lobe along the sweep
    assert len(jumps(v)) == 0, (name, jumps(v))


def rotated_table(table, seed=0):
    """The same LTCs with arbitrary representatives ``M Rz(gamma)`` (eq. 11): what an
    unaligned fitter may return for every entry."""
    rng = np.random.default_rng(seed)
    R = rotation_z(rng.uniform(0, 2 * np.pi, table.shape))
    return AnisoGGXTable(table.axes, table.M @ R, table.magnitude, table.fresnel)


def test_without_alignment_sweeps_jump(table):
    """Unaligned matrices: identical LTCs at every node, yet the sweeps jump (seams at the
    symmetry folds, where a matrix meets its mirror image). Aligning them restores the table."""
    bad = rotated_table(table)
    # the same distributions at the nodes: shading at the grid's views is unchanged
    th, ph, al, ra = (a[[3, 5, 2, 4]] for a in table.axes)
    wo = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    q = quad_toward(np.array([0.2, 0.4, 0.9]))
    np.testing.assert_allclose(bad.shade(wo, al, al * ra, q), table.shade(wo, al, al * ra, q),
                               rtol=1e-9)
    n_jumps = 0
    for name, wo, ax, ay, quad in sweeps():
        n_jumps += len(jumps(bad.shade(wo, ax, ay, quad)))
    assert n_jumps >= 3
    # aligning the arbitrary representatives recovers the stored (aligned) matrices
    sub = np.random.default_rng(1).choice(table.M.size // 9, 128, replace=False)
    fixed = align(bad.M.reshape(-1, 3, 3)[sub])["M"]
    fixed /= np.linalg.norm(fixed[..., :, 2], axis=-1)[..., None, None]
    np.testing.assert_allclose(fixed, table.M.reshape(-1, 3, 3)[sub], atol=2e-3)


def test_unaligned_interpolation_departs_from_both_neighbours(table):
    """Fig. 7 (a1): blending two representatives of one LTC gives another distribution."""
    from prefilter.ltc import LTC
    from prefilter.sphere import uniform_sphere

    M = table.M[4, 3, 3, 2]
    w = uniform_sphere(np.random.default_rng(0).random((20000, 2)))
    ref = LTC(M).eval(w)
    mid_aligned = LTC(0.5 * (M + M)).eval(w)
    mid_unaligned = LTC(0.5 * (M + M @ rotation_z(2.0))).eval(w)
    l1 = lambda q: np.mean(np.abs(q - ref)) * 4 * np.pi  # noqa: E731
    assert l1(mid_aligned) < 1e-12
    assert l1(mid_unaligned) > 0.3
