"""``ltc-multiscale-aniso``: anisotropic meso-scale roughness from slope moments (beyond the paper).

Tao et al. 2021 reduce the footprint's normals to one number (the mean resultant length), so an
anisotropic normal distribution (brushed metal) gets an isotropic lobe. Here the footprint's
normals are described LEAN-style (Olano & Baker 2010) by the first and second moments of their
slopes ``s = (-n_x / n_z, -n_y / n_z)`` (a moments mip chain, ``prefilter.texture.moment_chain``):
mean slope -> shading normal, slope covariance ``Sigma_meso`` -> meso lobe. The micro-scale GGX
lobe is combined in slope space with the variance ``alpha^2 / 2`` per axis (LEADR,
``equations.md`` section 4), after converting the meso covariance to GGX roughness units:

    Sigma = C^2 Sigma_meso + diag(alpha_x^2, alpha_y^2) / 2,    alpha_i = sqrt(2 lambda_i(Sigma))

``C = GGX_PER_BECKMANN``: a Gaussian slope distribution of roughness ``alpha_B = sqrt(2 sigma^2)``
is best fitted (maximum likelihood, ``fit_alpha_ml``) by the GGX lobe of roughness ``0.78 alpha_B``
(isotropic; 0.73 for a one-dimensional spread); the heavier GGX tails need the smaller alpha.
Without ``C`` the brushed-map highlight loses half its energy. The result is shaded with the
anisotropic LTC table (``prefilter.ltc.AnisoGGXTable``) in the principal
frame of ``Sigma`` (x = eigenvector of the larger eigenvalue ``lambda_1``).
"""

from __future__ import annotations

import functools

import numpy as np

from prefilter.texture.mip import moment_chain

__all__ = ["COMBINE", "GGX_PER_BECKMANN", "aniso_attributes", "principal_axes",
           "render_multiscale_aniso", "slope_moments_chain"]

#: How micro and meso roughness combine: ``"lean"`` (variances add, default) or ``"fit"``
#: (our refit of eq. 7 per principal axis, ``alpha_meso_i = C sqrt(2 lambda_i(Sigma_meso))``).
COMBINE = ("lean", "fit")

#: GGX roughness per Beckmann roughness of the same Gaussian slope spread (ML fit, isotropic).
GGX_PER_BECKMANN = 0.78

#: Normals closer to the horizon than this (n_z) are clamped so their slopes stay finite.
NZ_MIN = 0.05


@functools.lru_cache(maxsize=16)
def _slope_chain(key):
    from prefilter.render.scene import load_texture

    return slope_moments_chain(load_texture(*key))


def slope_moments_chain(normals):
    """Moments mip chain (channels ``E[s_x], E[s_y], E[s_x^2], E[s_y^2], E[s_x s_y]``) of the
    slopes ``s = (-n_x, -n_y) / n_z`` of unit tangent-space normals ``(H, W, 3)``
    (LEAN mapping, Olano & Baker 2010 section 3)."""
    n = np.asarray(normals, dtype=np.float64)
    nz = np.maximum(n[..., 2], NZ_MIN)
    return moment_chain(np.stack([-n[..., 0] / nz, -n[..., 1] / nz], -1))


def principal_axes(cov):
    """Eigen-decomposition of symmetric 2x2 matrices ``(..., 2, 2)`` in closed form.

    Returns ``lambda_1 >= lambda_2 >= 0`` (each ``(...)``) and the unit eigenvector ``(..., 2)``
    of ``lambda_1`` (``(1, 0)`` for isotropic matrices).
    """
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    mean = 0.5 * (a + c)
    disc = np.sqrt(0.25 * (a - c) ** 2 + b * b)
    l1, l2 = mean + disc, np.maximum(mean - disc, 0.0)
    # the angle of the major axis: stable for b -> 0 and a ~ c
    phi = 0.5 * np.arctan2(2.0 * b, a - c)
    return l1, l2, np.stack([np.cos(phi), np.sin(phi)], -1)


def aniso_attributes(scene, g, *, combine: str = "lean", anisotropic_footprint: bool = False,
                     max_aniso: int = 8, lod_bias: float = 0.0) -> dict:
    """Shading frame (principal axes), material and roughness per hit sample of a flat G-buffer.

    Returns a dict with ``t, b, n`` (N, 3) (``t`` along the major axis of the combined slope
    covariance), ``alpha_x >= alpha_y`` (N,), ``base_color, f0`` (N, 3). Materials without a
    normal map use the micro roughness in the geometric frame (height maps: their slope moments,
    as ``leadr``). ``anisotropic_footprint`` averages ``ceil(major / minor)`` taps along the
    footprint's major axis (``MipChain.lookup_footprint``) instead of one isotropic tap;
    ``lod_bias`` scales the footprint by ``2^lod_bias``.
    """
    from prefilter.multiscale.convolution import _alpha_total
    from prefilter.multiscale.render import footprint_read
    from prefilter.render.driver import shading_frame, surface_attributes
    from prefilter.texture.mip import moments_to_stats

    if combine not in COMBINE:
        from prefilter.errors import PrefilterError

        raise PrefilterError(f"combine: expected one of {COMBINE}, got {combine!r}")

    def surface(mat, uv, dudv, gt, gb, gn):
        cnt = len(uv)
        chain = None
        if mat.normal_map is not None:
            chain = _slope_chain(mat.normal_map.cache_key())
        elif mat.height_map is not None:
            chain = mat.height_map.mip()
        mx = np.full(cnt, 0.5 * mat.alpha_x ** 2)
        my = np.full(cnt, 0.5 * mat.alpha_y ** 2)
        if chain is None:
            mean = np.zeros((cnt, 2))
            cov_meso = np.zeros((cnt, 2, 2))
        else:
            mean, cov_meso = moments_to_stats(
                footprint_read(chain, uv, dudv * 2.0 ** lod_bias, anisotropic_footprint,
                               max_aniso))
        if combine == "lean":
            cov = GGX_PER_BECKMANN ** 2 * cov_meso
            cov[:, 0, 0] += mx
            cov[:, 1, 1] += my
            l1, l2, e = principal_axes(cov)
            a1, a2 = np.sqrt(2.0 * l1), np.sqrt(2.0 * l2)
        else:
            l1, l2, e = principal_axes(cov_meso)
            a_mi = np.full(cnt, min(np.sqrt(mat.alpha_x * mat.alpha_y), 1.0))
            a1, a2 = (_alpha_total(a_mi, np.minimum(GGX_PER_BECKMANN * np.sqrt(2.0 * li), 1.0),
                                   "fit") for li in (l1, l2))
        # rotate the geometric tangent frame to the principal axes, then tilt it to the mean normal
        c, s = e[:, 0:1], e[:, 1:2]
        t_rot = c * gt + s * gb
        b_rot = -s * gt + c * gb
        nts_geo = np.stack([-mean[:, 0], -mean[:, 1], np.ones(cnt)], -1)
        # the same normal in the rotated (t_rot, b_rot, n) frame
        nts = np.stack([c[:, 0] * nts_geo[:, 0] + s[:, 0] * nts_geo[:, 1],
                        -s[:, 0] * nts_geo[:, 0] + c[:, 0] * nts_geo[:, 1], nts_geo[:, 2]], -1)
        t, b, n = shading_frame(t_rot, b_rot, gn, nts)
        return {"t": t, "b": b, "n": n, "alpha_x": np.minimum(a1, 1.0),
                "alpha_y": np.minimum(a2, 1.0)}

    return surface_attributes(scene, g, surface=surface)


def render_multiscale_aniso(scene, settings, *, combine: str = "lean",
                            anisotropic_footprint: bool = False, max_aniso: int = 8,
                            lod_bias: float = 0.0) -> np.ndarray:
    """The ``ltc-multiscale-aniso`` method (see the module docstring)."""
    from prefilter.ltc.aniso.render import shade_ltc_aniso
    from prefilter.ltc.aniso.table import AnisoGGXTable
    from prefilter.render.driver import render_samples
    from prefilter.render.lighttex import split_lights

    lights, textured = split_lights(scene, "ltc-multiscale-aniso")
    table = settings.table if isinstance(settings.table, AnisoGGXTable) else _aniso_table()

    def shade(g, _u):
        a = aniso_attributes(scene, g, combine=combine,
                             anisotropic_footprint=anisotropic_footprint, max_aniso=max_aniso,
                             lod_bias=lod_bias)
        return shade_ltc_aniso(g.position, a["t"], a["b"], a["n"], g.view, a["alpha_x"],
                               a["alpha_y"], a["base_color"], a["f0"], lights, table, textured)

    return render_samples(scene, settings, shade, stratified=settings.spp > 1,
                          desc="ltc-multiscale-aniso")


@functools.lru_cache(maxsize=1)
def _aniso_table():
    from prefilter.ltc.aniso.table import AnisoGGXTable

    return AnisoGGXTable.load()
