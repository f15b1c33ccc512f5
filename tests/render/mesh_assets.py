"""Small mesh files the mesh tests write (trimesh export): a UV-mapped quad that matches the
analytic plane and a UV sphere that matches the analytic sphere's parametrisation."""

from __future__ import annotations

import numpy as np
import trimesh


def _export(path, v, f, n, uv_render):
    """Write ``path`` (format by suffix); ``uv_render`` in the renderer's texture space (v down
    the image), stored in the files' OBJ convention (v up)."""
    uv = np.stack([uv_render[:, 0], 1.0 - uv_render[:, 1]], -1)
    m = trimesh.Trimesh(v, f, vertex_normals=n, process=False,
                        visual=trimesh.visual.TextureVisuals(uv=uv))
    m.export(str(path))
    return path


def quad_arrays(size=(4.0, 4.0)):
    """The analytic default plane (normal +y, tangent +x, centre 0) of ``size`` as two
    triangles: ``(vertices, faces, normals, uv)`` with ``uv = (x / sx + 0.5, -z / sz + 0.5)``."""
    sx, sz = size
    c = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float) * [sx / 2, sz / 2]
    v = np.stack([c[:, 0], np.zeros(4), c[:, 1]], -1)
    uv = np.stack([v[:, 0] / sx + 0.5, -v[:, 2] / sz + 0.5], -1)
    return v, np.array([[0, 2, 1], [0, 3, 2]]), np.tile([0.0, 1.0, 0.0], (4, 1)), uv


def write_quad(path, size=(4.0, 4.0)):
    return _export(path, *quad_arrays(size))


def uv_sphere_arrays(n_theta: int, n_phi: int, radius: float = 1.0):
    """A UV sphere on the analytic sphere's parametrisation (pole +y, phi from +x towards +z):
    ``p = r (sin t cos f, cos t, sin t sin f)``, ``uv = (f / 2pi, t / pi)``, a seam of duplicated
    vertices at ``f = 0, 2pi`` and one pole vertex per segment (at the segment's mid ``u``);
    outward normals; ``2 n_phi (n_theta - 1)`` triangles."""
    i, j = np.meshgrid(np.arange(n_theta + 1), np.arange(n_phi + 1), indexing="ij")
    u = j / n_phi
    u = np.where(i == 0, (j - 0.5) / n_phi, np.where(i == n_theta, (j + 0.5) / n_phi, u))
    th, ph = np.pi * i / n_theta, 2 * np.pi * u
    n = np.stack([np.sin(th) * np.cos(ph), np.cos(th), np.sin(th) * np.sin(ph)], -1)
    uv = np.stack([u, i / n_theta], -1)
    idx = i * (n_phi + 1) + j
    a, b = idx[:-1, :-1], idx[:-1, 1:]
    d, c = idx[1:, :-1], idx[1:, 1:]
    upper = np.stack([a, b, d], -1)[1:]  # (a, b) is the north pole on row 0
    lower = np.stack([b, c, d], -1)[:-1]  # (c, d) is the south pole on the last row
    f = np.concatenate([upper.reshape(-1, 3), lower.reshape(-1, 3)])
    # two pole vertices belong to no triangle: drop them (the PLY reader would, with the normals)
    used = np.zeros(idx.size, bool)
    used[f] = True
    new = np.cumsum(used) - 1
    return (radius * n.reshape(-1, 3)[used], new[f], n.reshape(-1, 3)[used],
            uv.reshape(-1, 2)[used])


def write_uv_sphere(path, n_theta: int, n_phi: int, radius: float = 1.0):
    return _export(path, *uv_sphere_arrays(n_theta, n_phi, radius))
