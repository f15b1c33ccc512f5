"""Triangle meshes: loading (OBJ, PLY, glTF 2.0 through trimesh), tangents, Embree intersection
and ray-differential footprints.

Conventions (``docs/meshes.md``):

- Texture coordinates follow the renderer's texture space (``v`` down the image rows, row 0 at
  ``v = 0``): trimesh reads every format into the OBJ convention (``v`` up the image, glTF
  flipped on load), so ``uv = (u_file, 1 - v_obj)``; glTF coordinates come out as stored.
- Vertex normals come from the file where it has them, else trimesh's averaged face
  normals. The G-buffer normal of a mesh hit is the interpolated vertex normal (smooth shading).
- Tangents ``(V, 4) = (t, w)`` are computed from the UVs per vertex the way MikkTSpace does
  (:func:`vertex_tangents`); the bitangent is ``b = w (n x t)``, pointing along ``+v``, so
  ``t x b = w n``: the frame is right-handed (``w = 1``) unless the UVs are mirrored.
- Footprints: Igehy 1999 ray differentials on the triangle's plane (its first-order surface),
  UV Jacobian from the barycentric gradients (:func:`mesh_hits_kernel`).

Embree (``embreex``, through :class:`trimesh.ray.ray_pyembree.RayMeshIntersector`) finds the
nearest triangle in float32; the hit is then recomputed in float64 on that triangle
(Moeller-Trumbore), so a mesh plane and the analytic plane agree to rounding.
"""

from __future__ import annotations

import functools
import math
import weakref
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from prefilter.errors import PrefilterError
from prefilter.jit import njit_parallel, prange, serial
from prefilter.validation import check_memory

__all__ = ["BYTES_PER_TRIANGLE", "MESH_SUFFIXES", "Mesh", "MeshData", "check_mesh_memory",
           "load_mesh", "non_manifold_edges", "mesh_hits_kernel", "trace_objects",
           "transform_matrix", "vertex_tangents"]

MESH_SUFFIXES = (".obj", ".ply", ".gltf", ".glb")
_EPS = 1e-9  # smallest ray parameter of a hit (as the analytic kernels)


@dataclass(frozen=True, eq=False)
class MeshData:
    """World-space triangles: ``vertices (V, 3)``, ``faces (F, 3)`` int64, ``normals (V, 3)``
    unit, ``uv (V, 2)`` (renderer texture space) or ``None``, ``tangents (V, 4)`` (unit ``t``,
    handedness ``w = +-1``; from an arbitrary ``t`` orthogonal to ``n`` when there are no UVs)."""

    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    uv: np.ndarray | None
    tangents: np.ndarray


@dataclass(frozen=True, eq=False)
class Mesh:
    """A scene object: the triangles of ``file`` under ``transform (4, 4)`` with ``material``
    (a :class:`prefilter.render.scene.Material`); ``data`` holds the world-space arrays."""

    file: Path
    transform: np.ndarray
    material: object
    data: MeshData
    type: str = "mesh"


# -- loading ---------------------------------------------------------------------------------------


def transform_matrix(translate=(0.0, 0.0, 0.0), rotate=(0.0, 0.0, 0.0), scale=1.0) -> np.ndarray:
    """``(4, 4)`` matrix ``T R S``: scale, then rotate about x, y, z (degrees, in that order),
    then translate."""
    rx, ry, rz = np.radians(np.asarray(rotate, dtype=np.float64))

    def rot(a, i, j):
        m = np.eye(3)
        m[i, i] = m[j, j] = np.cos(a)
        m[i, j], m[j, i] = -np.sin(a), np.sin(a)
        return m

    m = np.eye(4)
    m[:3, :3] = rot(rz, 0, 1) @ rot(ry, 2, 0) @ rot(rx, 1, 2) @ np.diag(
        np.broadcast_to(np.asarray(scale, dtype=np.float64), 3))
    m[:3, 3] = translate
    return m


def _read(path: Path):
    """``(vertices, faces, normals, uv or None)`` of a mesh file (trimesh; uv in the OBJ
    convention). A glTF scene's meshes are placed by their node transforms and concatenated."""
    import trimesh

    try:
        loaded = trimesh.load(str(path), process=False)
        if isinstance(loaded, trimesh.Scene):
            # the scene's meshes where its nodes place them (Scene.dump would drop the normals)
            parts = [(loaded.geometry[name], mat) for mat, name in
                     (loaded.graph[node] for node in loaded.graph.nodes_geometry)]
        else:
            parts = [(loaded, np.eye(4))]
    except Exception as exc:  # trimesh raises many types for a bad file
        raise PrefilterError(f"{path}: unreadable mesh file ({type(exc).__name__}: {exc})") \
            from None
    parts = [(m, a) for m, a in parts if isinstance(m, trimesh.Trimesh) and len(m.faces)]
    if not parts:
        raise PrefilterError(f"{path}: expected a mesh with triangles, got none")
    vs, fs, ns, uvs, offset = [], [], [], [], 0
    for m, a in parts:
        a = np.asarray(a, dtype=np.float64)
        v = np.asarray(m.vertices, dtype=np.float64) @ a[:3, :3].T + a[:3, 3]
        vs.append(v)
        fs.append(np.asarray(m.faces, dtype=np.int64) + offset)
        with np.errstate(all="ignore"):  # NaN vertices are reported by the caller
            ns.append(np.asarray(m.vertex_normals, dtype=np.float64) @ np.linalg.inv(a[:3, :3]))
        uv = getattr(m.visual, "uv", None)
        uvs.append(None if uv is None or len(uv) != len(v) else np.asarray(uv, np.float64))
        offset += len(v)
    uv = None if any(u is None for u in uvs) else np.concatenate(uvs)
    return np.concatenate(vs), np.concatenate(fs), np.concatenate(ns), uv


def _unit(a, fallback=None):
    n = np.linalg.norm(a, axis=-1, keepdims=True)
    out = a / np.maximum(n, 1e-300)
    if fallback is not None:
        out = np.where(n > 1e-20, out, fallback)
    return out


def _any_perpendicular(n):
    """Unit vectors ``(..., 3)`` orthogonal to unit ``n (..., 3)`` (Duff et al. 2017)."""
    s = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    return np.stack([1.0 + s * n[..., 0] ** 2 * a, s * b, -s * n[..., 0]], -1)


def vertex_tangents(vertices, faces, normals, uv) -> np.ndarray:
    """Per-vertex tangents ``(V, 4) = (t, w)`` from UVs, the MikkTSpace way.

    Per triangle the UV derivatives ``dp/du, dp/dv`` (Lengyel 2001: solve
    ``[e1 e2] = [dp/du dp/dv] [duv1 duv2]``); each vertex accumulates the unit ``dp/du`` and
    ``dp/dv`` of its triangles weighted by the corner angle (as MikkTSpace), then ``t`` is
    Gram-Schmidt orthogonalised against the vertex normal and ``w = sign((n x t) . dp/dv)``.
    Triangles with degenerate UVs add nothing; vertices left without a tangent get one
    orthogonal to ``n`` (and ``w = 1``). ``uv`` in the renderer's texture space: ``b = w n x t``
    points along ``+v``.
    """
    v, f = np.asarray(vertices, float), np.asarray(faces, np.int64)
    p0, p1, p2 = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    t0, t1, t2 = uv[f[:, 0]], uv[f[:, 1]], uv[f[:, 2]]
    e1, e2 = p1 - p0, p2 - p0
    d1, d2 = t1 - t0, t2 - t0
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-20
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    dpdu = _unit((e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * inv)
    dpdv = _unit((e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * inv)
    tacc = np.zeros_like(v)
    bacc = np.zeros_like(v)
    corners = ((0, 1, 2), (1, 2, 0), (2, 0, 1))
    for i, j, k in corners:
        a = _unit(v[f[:, j]] - v[f[:, i]])
        b = _unit(v[f[:, k]] - v[f[:, i]])
        w = np.arccos(np.clip(np.sum(a * b, -1), -1.0, 1.0))[:, None] * ok[:, None]
        np.add.at(tacc, f[:, i], w * dpdu)
        np.add.at(bacc, f[:, i], w * dpdv)
    n = np.asarray(normals, float)
    t = tacc - np.sum(tacc * n, -1, keepdims=True) * n
    t = _unit(t, _any_perpendicular(n))
    w = np.where(np.sum(np.cross(n, t) * bacc, -1) < 0.0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], -1)


def _needs_uv(material) -> str | None:
    """The material field that needs texture coordinates, or ``None``."""
    for k in ("normal_map", "height_map", "color_map"):
        if getattr(material, k, None) is not None:
            return k
    if getattr(material, "alpha_x", 0.0) != getattr(material, "alpha_y", 0.0):
        return "alpha_x"  # anisotropy follows the tangent (+u)
    return None


#: Peak memory of loading and first tracing a mesh, per triangle (bytes): :class:`MeshData`,
#: trimesh's copies while reading and Embree's scene and BVH; measured 392-526 B on UV spheres
#: of 1M-10M triangles (benchmarks/bench_mesh_large.py, docs/meshes.md "Large meshes").
BYTES_PER_TRIANGLE = 550
#: Memory per byte of file, before the triangles are counted: a binary PLY holds 33 B a
#: triangle (measured), so 550 / 33; OBJ text about 80 B a triangle. A .gltf is counted by its
#: JSON only (its .bin buffers are checked by the triangle count after reading).
_BYTES_PER_FILE_BYTE = {".ply": 17, ".glb": 17, ".obj": 7, ".gltf": 17}


def _ply_counts(path: Path) -> tuple[int, int] | None:
    """``(vertices, faces)`` declared by a PLY header, or None where the header does not say."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        return None
    counts = {}
    for line in head[:end].decode("ascii", "replace").splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0] == "element" and parts[2].isdigit():
            counts[parts[1]] = int(parts[2])
    return counts.get("vertex", 0), counts.get("face", 0)


def check_mesh_memory(p: Path) -> None:
    """Refuse, before reading, a mesh file whose triangles would not fit the memory budget
    (:func:`prefilter.validation.check_memory`): the PLY header's face count, else an estimate
    from the file's size."""
    counts = _ply_counts(p) if p.suffix.lower() == ".ply" else None
    if counts is not None:
        check_memory(counts[1] * BYTES_PER_TRIANGLE + counts[0] * 64,
                     f"{p}: a mesh of {counts[1]:,} triangles (its PLY header)")
    else:
        size = p.stat().st_size
        check_memory(size * _BYTES_PER_FILE_BYTE.get(p.suffix.lower(), 17),
                     f"{p}: reading a mesh file of {size / 2**20:.1f} MiB")


def non_manifold_edges(faces) -> np.ndarray:
    """Edges ``(K, 2)`` (vertex indices, sorted) shared by more than two of ``faces (F, 3)``."""
    f = np.asarray(faces, dtype=np.int64)
    n = int(f.max()) + 1
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    u, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    bad = u[counts > 2]
    return np.stack([bad // n, bad % n], axis=1)


@functools.lru_cache(maxsize=16)
def _load_cached(path: str, mtime: int, transform: bytes) -> MeshData:
    p = Path(path)
    check_mesh_memory(p)
    v, f, n, uv = _read(p)
    # the file's own count, for the formats whose size alone estimated it
    check_memory(len(f) * BYTES_PER_TRIANGLE, f"{p}: a mesh of {len(f):,} triangles")
    if not np.all(np.isfinite(v)):
        raise PrefilterError(f"{p}: expected finite vertex positions, got NaN or inf")
    if f.min() < 0 or f.max() >= len(v):
        raise PrefilterError(f"{p}: expected face indices in [0, {len(v)}), got "
                             f"[{f.min()}, {f.max()}]")
    bad = non_manifold_edges(f)
    if len(bad):
        # an edge of three or more triangles has no one side: the smooth normals and the
        # UV tangents averaged across it (and the ray differentials built on them) are undefined
        raise PrefilterError(
            f"{p}: expected a manifold mesh, got {len(bad)} edge(s) shared by more than two "
            f"triangles (the first between vertices {bad[0, 0]} and {bad[0, 1]}); split them "
            f"into separate surfaces (e.g. separate objects or duplicated vertices)")
    m = np.frombuffer(transform, dtype=np.float64).reshape(4, 4)
    v = v @ m[:3, :3].T + m[:3, 3]
    # normals transform by the inverse transpose (row vectors: n M^-1)
    n = n @ np.linalg.inv(m[:3, :3])
    bad = ~np.all(np.isfinite(n), -1) | (np.linalg.norm(n, axis=-1) < 1e-12)
    if np.any(bad):  # vertices of degenerate faces only: the area-weighted face normals
        fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        acc = np.zeros_like(v)
        for c in range(3):
            np.add.at(acc, f[:, c], fn)
        n[bad] = acc[bad]
    n = _unit(n, np.array([0.0, 0.0, 1.0]))
    if uv is not None:
        if not np.all(np.isfinite(uv)):
            raise PrefilterError(f"{p}: expected finite texture coordinates, got NaN or inf")
        uv = np.stack([uv[:, 0], 1.0 - uv[:, 1]], -1)  # OBJ convention -> v down the image
        tan = vertex_tangents(v, f, n, uv)
    else:
        tan = np.concatenate([_any_perpendicular(n), np.ones((len(v), 1))], -1)
    return MeshData(v, f, n, uv, tan)


def load_mesh(path, transform=None, material=None, where: str = "") -> MeshData:
    """World-space :class:`MeshData` of mesh file ``path`` (``.obj``, ``.ply``, ``.gltf``,
    ``.glb``) under ``transform (4, 4)`` (default identity), cached by path, modification time
    and transform.

    Raises :class:`PrefilterError` (prefixed with ``where``, a scene field path) for a missing,
    unreadable or empty file, a file too large for the memory budget (checked before reading),
    NaN vertices, a non-manifold mesh (an edge of more than two triangles), or a mesh without
    UVs whose ``material`` needs them (textures, anisotropic roughness).
    """
    p = Path(path)
    pre = f"{where}: " if where else ""
    if p.suffix.lower() not in MESH_SUFFIXES:
        raise PrefilterError(f"{pre}expected a {'/'.join(MESH_SUFFIXES)} file, got {str(p)!r}")
    if not p.is_file():
        raise PrefilterError(f"{pre}mesh file not found: {p}")
    m = np.eye(4) if transform is None else np.asarray(transform, dtype=np.float64)
    try:
        data = _load_cached(str(p.resolve()), p.stat().st_mtime_ns, m.tobytes())
    except PrefilterError as exc:
        raise PrefilterError(f"{pre}{exc}") from None
    need = _needs_uv(material)
    if data.uv is None and need is not None:
        raise PrefilterError(f"{pre}{p} has no texture coordinates (UVs), but the material's "
                             f"{need} needs them")
    return data


# -- intersection ----------------------------------------------------------------------------------

_INTERSECTORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _intersector(data: MeshData):
    """The Embree scene of ``data`` (built once per mesh)."""
    it = _INTERSECTORS.get(data)
    if it is None:
        import trimesh
        from trimesh.ray.ray_pyembree import RayMeshIntersector

        it = RayMeshIntersector(trimesh.Trimesh(data.vertices, data.faces, process=False))
        _INTERSECTORS[data] = it
    return it


@njit_parallel
def mesh_hits_kernel(o, d, ddx, ddy, tri, object_id, vertices, faces, normals, tangents, uvs,
                     hit, oid, pos, nrm, tan, bit, uv, dudv, dpdx, dpdy, dist):
    """Rays ``o, d, ddx, ddy (N, 3)`` on triangles ``tri (N,)`` (-1: no hit) of one mesh: where
    the hit is nearer than ``dist``, write its G-buffer row (as
    :class:`prefilter.render.camera.GBuffer`) with ``oid = object_id``.

    The hit in float64 (Moeller and Trumbore 1997); its ray differentials by Igehy 1999, eq. 10,
    on the triangle's plane (normal ``nf``): ``dp/dx = t (dd/dx - (nf . dd/dx) / (nf . d) d)``;
    the barycentrics' derivatives solve ``dp = e1 db1 + e2 db2`` on that plane (the Gram matrix
    of ``e1, e2``); ``d uv / d pixel = sum_i uv_i d b_i / d pixel``. Normal: the interpolated
    vertex normal; tangent: the interpolated tangent made orthogonal to it; bitangent
    ``w (n x t)``, ``w`` the sign of the interpolated handedness.
    """
    for i in prange(tri.shape[0]):
        f = tri[i]
        if f < 0:
            continue
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        p0x, p0y, p0z = vertices[i0, 0], vertices[i0, 1], vertices[i0, 2]
        e1x, e1y, e1z = vertices[i1, 0] - p0x, vertices[i1, 1] - p0y, vertices[i1, 2] - p0z
        e2x, e2y, e2z = vertices[i2, 0] - p0x, vertices[i2, 1] - p0y, vertices[i2, 2] - p0z
        dx, dy, dz = d[i, 0], d[i, 1], d[i, 2]
        pvx, pvy, pvz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
        det = e1x * pvx + e1y * pvy + e1z * pvz
        if not abs(det) > 1e-300:
            continue
        inv = 1.0 / det
        tvx, tvy, tvz = o[i, 0] - p0x, o[i, 1] - p0y, o[i, 2] - p0z
        b1 = (tvx * pvx + tvy * pvy + tvz * pvz) * inv
        qvx, qvy, qvz = tvy * e1z - tvz * e1y, tvz * e1x - tvx * e1z, tvx * e1y - tvy * e1x
        b2 = (dx * qvx + dy * qvy + dz * qvz) * inv
        t = (e2x * qvx + e2y * qvy + e2z * qvz) * inv
        if not (t > _EPS and t < dist[i]):
            continue
        nfx, nfy, nfz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
        dn = dx * nfx + dy * nfy + dz * nfz  # the scale of nf cancels in the ratios
        fx = (ddx[i, 0] * nfx + ddx[i, 1] * nfy + ddx[i, 2] * nfz) / dn
        fy = (ddy[i, 0] * nfx + ddy[i, 1] * nfy + ddy[i, 2] * nfz) / dn
        ax, ay, az = t * (ddx[i, 0] - fx * dx), t * (ddx[i, 1] - fx * dy), t * (ddx[i, 2] - fx * dz)
        bx, by, bz = t * (ddy[i, 0] - fy * dx), t * (ddy[i, 1] - fy * dy), t * (ddy[i, 2] - fy * dz)
        g11 = e1x * e1x + e1y * e1y + e1z * e1z
        g12 = e1x * e2x + e1y * e2y + e1z * e2z
        g22 = e2x * e2x + e2y * e2y + e2z * e2z
        idet = 1.0 / max(g11 * g22 - g12 * g12, 1e-300)
        r1, r2 = e1x * ax + e1y * ay + e1z * az, e2x * ax + e2y * ay + e2z * az
        c1x, c2x = (g22 * r1 - g12 * r2) * idet, (g11 * r2 - g12 * r1) * idet
        r1, r2 = e1x * bx + e1y * by + e1z * bz, e2x * bx + e2y * by + e2z * bz
        c1y, c2y = (g22 * r1 - g12 * r2) * idet, (g11 * r2 - g12 * r1) * idet
        w0 = 1.0 - b1 - b2
        n0 = w0 * normals[i0, 0] + b1 * normals[i1, 0] + b2 * normals[i2, 0]
        n1 = w0 * normals[i0, 1] + b1 * normals[i1, 1] + b2 * normals[i2, 1]
        n2 = w0 * normals[i0, 2] + b1 * normals[i1, 2] + b2 * normals[i2, 2]
        ln = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        n0, n1, n2 = n0 / ln, n1 / ln, n2 / ln
        t0 = w0 * tangents[i0, 0] + b1 * tangents[i1, 0] + b2 * tangents[i2, 0]
        t1 = w0 * tangents[i0, 1] + b1 * tangents[i1, 1] + b2 * tangents[i2, 1]
        t2 = w0 * tangents[i0, 2] + b1 * tangents[i1, 2] + b2 * tangents[i2, 2]
        hw = w0 * tangents[i0, 3] + b1 * tangents[i1, 3] + b2 * tangents[i2, 3]
        tn = t0 * n0 + t1 * n1 + t2 * n2
        t0, t1, t2 = t0 - tn * n0, t1 - tn * n1, t2 - tn * n2
        lt = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
        if lt > 1e-12:
            t0, t1, t2 = t0 / lt, t1 / lt, t2 / lt
        else:  # any unit vector orthogonal to n (Duff et al. 2017)
            sg = 1.0 if n2 >= 0.0 else -1.0
            a = -1.0 / (sg + n2)
            t0, t1, t2 = 1.0 + sg * n0 * n0 * a, sg * n0 * n1 * a, -sg * n0
        hand = -1.0 if hw < 0.0 else 1.0
        hit[i] = True
        oid[i] = object_id
        dist[i] = t
        pos[i, 0], pos[i, 1], pos[i, 2] = o[i, 0] + t * dx, o[i, 1] + t * dy, o[i, 2] + t * dz
        nrm[i, 0], nrm[i, 1], nrm[i, 2] = n0, n1, n2
        tan[i, 0], tan[i, 1], tan[i, 2] = t0, t1, t2
        bit[i, 0] = hand * (n1 * t2 - n2 * t1)
        bit[i, 1] = hand * (n2 * t0 - n0 * t2)
        bit[i, 2] = hand * (n0 * t1 - n1 * t0)
        dpdx[i, 0], dpdx[i, 1], dpdx[i, 2] = ax, ay, az
        dpdy[i, 0], dpdy[i, 1], dpdy[i, 2] = bx, by, bz
        for c in range(2):
            u0, u1, u2 = uvs[i0, c], uvs[i1, c], uvs[i2, c]
            uv[i, c] = w0 * u0 + b1 * u1 + b2 * u2
            dudv[i, c, 0] = (u1 - u0) * c1x + (u2 - u0) * c2x
            dudv[i, c, 1] = (u1 - u0) * c1y + (u2 - u0) * c2y


def trace_objects(objects, o, d, ddx, ddy) -> dict:
    """Nearest hits of rays ``o, d, ddx, ddy (N, 3)`` with ``objects`` (planes and spheres by the
    Numba kernel, meshes by Embree): the flat G-buffer fields of
    :class:`prefilter.render.camera.GBuffer` as a dict, ``object_id`` indexing ``objects``."""
    from prefilter.render.kernels import gbuffer_rays_kernel, pack_objects

    n = len(d)
    out = {"hit": np.zeros(n, bool), "object_id": np.full(n, -1, np.int32),
           "position": np.zeros((n, 3)), "normal": np.zeros((n, 3)),
           "tangent": np.zeros((n, 3)), "bitangent": np.zeros((n, 3)), "uv": np.zeros((n, 2)),
           "dudv": np.zeros((n, 2, 2)), "dpdx": np.zeros((n, 3)), "dpdy": np.zeros((n, 3)),
           "distance": np.full(n, np.inf), "view": -d, "direction": d.copy()}
    analytic = [i for i, obj in enumerate(objects) if obj.type != "mesh"]
    if analytic:
        types, params = pack_objects([objects[i] for i in analytic])
        order = ("hit", "object_id", "position", "normal", "tangent", "bitangent", "uv", "dudv",
                 "dpdx", "dpdy", "distance", "view", "direction")
        serial(gbuffer_rays_kernel, n)(o, d, ddx, ddy, types, params, *(out[k] for k in order))
        h = out["hit"]
        out["object_id"][h] = np.asarray(analytic, np.int32)[out["object_id"][h]]
    for i, obj in enumerate(objects):
        if obj.type != "mesh":
            continue
        data = obj.data
        tri = np.asarray(_intersector(data).intersects_first(o, d), dtype=np.int64)
        uvs = data.uv if data.uv is not None else np.zeros((len(data.vertices), 2))
        serial(mesh_hits_kernel, n)(o, d, ddx, ddy, tri, i, data.vertices, data.faces,
                                    data.normals, data.tangents, uvs, out["hit"],
                                    out["object_id"], out["position"], out["normal"],
                                    out["tangent"], out["bitangent"], out["uv"], out["dudv"],
                                    out["dpdx"], out["dpdy"], out["distance"])
    return out
