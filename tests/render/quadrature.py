"""Composite Gauss-Legendre quadrature over a parallelogram light, in the solid-angle measure
seen from a point: the independent check of closed-form light integrals and of the estimators."""

from __future__ import annotations

import numpy as np


def parallelogram_rule(vertices, origin=(0.0, 0.0, 0.0), normal=None, panels=48, order=8):
    """Nodes and weights of ``integral g(wi) cos_l / d^2 dA`` over the parallelogram
    ``v0 + s (v1 - v0) + t (v3 - v0)``: ``sum(g(wi) * weight)``.

    ``vertices`` (4, 3); ``normal`` (3,) the emitting side (default: the unit ``e1 x e3``).
    Returns ``wi`` (N, 3) unit directions from ``origin`` and ``weight`` (N,) (zero behind the
    light).
    """
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(0.0, 1.0, panels + 1)
    half = (edges[1:, None] - edges[:-1, None]) / 2
    s = ((edges[:-1, None] + edges[1:, None]) / 2 + half * x).ravel()
    ws = (half * w).ravel()
    S, T = np.meshgrid(s, s, indexing="ij")
    W = np.outer(ws, ws).ravel()
    v = np.asarray(vertices, float)
    e1, e3 = v[1] - v[0], v[3] - v[0]
    y = v[0] + S.ravel()[:, None] * e1 + T.ravel()[:, None] * e3 - np.asarray(origin, float)
    n = np.cross(e1, e3)
    area = np.linalg.norm(n)
    n = n / area if normal is None else np.asarray(normal, float)
    d2 = np.sum(y * y, axis=-1)
    wi = y / np.sqrt(d2)[:, None]
    cos_l = np.maximum(0.0, -(wi @ n))
    return wi, cos_l / d2 * area * W
