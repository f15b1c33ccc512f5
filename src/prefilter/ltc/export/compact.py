"""Compact encodings of the isotropic GGX table: binary16 texels and Chebyshev coefficients.

Both encode, per ``(t, r)`` node of :class:`~prefilter.ltc.table.GGXTable`, the six numbers an
engine stores (:func:`~prefilter.ltc.export.layout.inverse_texels` ``(m00, m20, m02, m22)`` of
``M^-1 / (M^-1)_11``, magnitude ``n`` and Fresnel ``f5``):

* ``half``: the six numbers as IEEE binary16 (12 bytes per node);
* ``fit``: each number as a tensor-product Chebyshev series of degree ``(dt, dr)`` in
  ``x_t = 2 t / t_max - 1`` and ``x_r = 2 (r - r_min) / (1 - r_min) - 1`` (least squares over the
  nodes; float32 coefficients, ``6 (dt + 1) (dr + 1)`` of them).

:func:`decode` turns either back into a :class:`GGXTable` on the table's own nodes (forward ``M``
with a unit third column), so :func:`compare_encodings` measures them with the acceptance
protocol of ``prefilter validate`` (:mod:`prefilter.ltc.validate`).
"""

from __future__ import annotations

import numpy as np
from numpy.polynomial import chebyshev

from prefilter.errors import PrefilterError
from prefilter.ltc.export.layout import inverse_texels

__all__ = ["ENCODINGS", "compare_encodings", "decode", "encode", "encoded_bytes", "node_values"]

ENCODINGS = ("half", "fit")
#: Chebyshev degrees (view, roughness) of the ``fit`` encoding.
FIT_DEGREE = (10, 10)


def node_values(table) -> np.ndarray:
    """``(T, R, 6)``: ``(m00, m20, m02, m22)`` of ``M^-1 / (M^-1)_11``, ``n``, ``f5``."""
    return np.concatenate([inverse_texels(table.M), table.magnitude[..., None],
                           table.fresnel[..., None]], -1)


def _chebyshev_coordinates(axis_t, axis_r):
    """``(x_t, x_r)``, each ``(T, R)``, the nodes mapped to ``[-1, 1]``."""
    xt = 2.0 * axis_t / axis_t[-1] - 1.0
    xr = 2.0 * (axis_r - axis_r[0]) / (1.0 - axis_r[0]) - 1.0
    return np.meshgrid(xt, xr, indexing="ij")


def encode(table, encoding: str, degree: tuple[int, int] = FIT_DEGREE) -> dict:
    """The ``encoding`` (``"half"`` or ``"fit"``) of ``table``: a dict of arrays.

    ``half``: ``texels (T, R, 6) uint16`` (binary16 bits). ``fit``: ``coefficients
    (6, dt + 1, dr + 1) float32`` (``numpy.polynomial.chebyshev.chebval2d`` order).
    Both carry the axes ``axis_t``, ``axis_r``.
    """
    values = node_values(table)
    axes = {"axis_t": table.axis_t, "axis_r": table.axis_r}
    if encoding == "half":
        return {"texels": values.astype(np.float16).view(np.uint16), **axes}
    if encoding == "fit":
        dt, dr = degree
        xt, xr = _chebyshev_coordinates(table.axis_t, table.axis_r)
        V = chebyshev.chebvander2d(xt, xr, [dt, dr]).reshape(xt.size, -1)
        coef, *_ = np.linalg.lstsq(V, values.reshape(xt.size, 6), rcond=None)
        return {"coefficients": coef.T.reshape(6, dt + 1, dr + 1).astype(np.float32), **axes}
    raise PrefilterError(f"encoding: expected one of {', '.join(ENCODINGS)}, got {encoding!r}")


def encoded_bytes(encoded: dict) -> int:
    """Bytes of the payload (texels or coefficients; the axes are two numbers each)."""
    payload = encoded["texels"] if "texels" in encoded else encoded["coefficients"]
    return int(payload.nbytes)


def decode(encoded: dict):
    """The :class:`GGXTable` an encoding stands for, on its own ``(axis_t, axis_r)`` nodes."""
    from prefilter.ltc.table import GGXTable

    axis_t, axis_r = np.asarray(encoded["axis_t"]), np.asarray(encoded["axis_r"])
    if "texels" in encoded:
        values = np.asarray(encoded["texels"], np.uint16).view(np.float16).astype(np.float64)
    else:
        coef = np.asarray(encoded["coefficients"], np.float64)
        xt, xr = _chebyshev_coordinates(axis_t, axis_r)
        values = np.stack([chebyshev.chebval2d(xt, xr, c) for c in coef], -1)
    Minv = np.zeros(values.shape[:-1] + (3, 3))
    Minv[..., 0, 0], Minv[..., 2, 0] = values[..., 0], values[..., 1]
    Minv[..., 0, 2], Minv[..., 2, 2] = values[..., 2], values[..., 3]
    Minv[..., 1, 1] = 1.0
    M = np.linalg.inv(Minv)
    M = M / np.linalg.norm(M[..., :, 2], axis=-1)[..., None, None]
    return GGXTable(axis_t, axis_r, M, values[..., 4], values[..., 5],
                    settings={"encoding": "half" if "texels" in encoded else "fit"})


def compare_encodings(table, n_configs: int = 2000, n_samples: int = 100_000, seed=0, *,
                      thresholds=(1e-3, 0.05), degree: tuple[int, int] = FIT_DEGREE,
                      progress: bool = False) -> dict:
    """Acceptance statistics of the full table and its ``half`` and ``fit`` encodings.

    The configurations and Monte Carlo references are those of
    :func:`prefilter.ltc.validate.run_acceptance` with the same ``seed`` (computed once, shared by
    the three tables). Returns ``{name: {"bytes": ..., "stats": {threshold: error_statistics}}}``
    with ``name`` in ``full`` (float32 payload of the six numbers), ``half``, ``fit``.
    """
    from prefilter.sphere.polygon import polygon_integral
    from prefilter.ltc.validate import (clip_to_horizon, error_statistics, random_configurations,
                                        reference_quad_integral)
    from prefilter.microfacet import GGX
    from prefilter.validation import as_rng

    rng = as_rng(seed, "seed")
    cfg = random_configurations(n_configs, rng)
    ref = np.zeros(n_configs)
    it = range(n_configs)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="MC references", unit="config")
    for i in it:
        ref[i], _ = reference_quad_integral(GGX(cfg["alpha"][i]), cfg["wo"][i], cfg["quad"][i],
                                            n_samples, rng)
    theta = np.arccos(np.clip(cfg["wo"][:, 2], -1, 1))
    quads = clip_to_horizon(cfg["quad"])
    encoded = {name: encode(table, name, degree) for name in ENCODINGS}
    tables = {"full": table, **{name: decode(e) for name, e in encoded.items()}}
    sizes = {"full": int(node_values(table).astype(np.float32).nbytes),
             **{name: encoded_bytes(e) for name, e in encoded.items()}}
    out = {}
    for name, t in tables.items():
        M, mag, _ = t.lookup(cfg["wo"], cfg["alpha"])
        est = mag * polygon_integral(M, quads)
        out[name] = {"bytes": sizes[name], "stats": {
            float(th): error_statistics(est, ref, theta, cfg["alpha"], threshold=th, albedo=mag)
            for th in thresholds}}
    return out
