"""The isotropic GGX LTC table: loading, validation and bilinear lookup.

Heitz, Dupuy, Hill, Neubelt 2016, section 4: one LTC matrix, a magnitude and a Fresnel scalar per
(view angle, roughness). The file layout is documented in ``docs/ltc.md`` and in
:meth:`GGXTable.load`; the table is produced by ``prefilter bake ltc-iso``
(:func:`prefilter.ltc.fit_iso.bake_table`).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from prefilter.fileio import (META_KEY, expect_array, expect_json_object, expect_table_header,
                           read_npz, table_source, verify_npz)
from prefilter.validation import (as_float_array, as_roughness, as_unit_interval,
                                 as_upper_directions, broadcast_batch)
from prefilter.errors import PrefilterError, TableFileError
from prefilter.ltc.fit_iso import TABLE_VERSION, default_table_path, shipped_table_path

_log = logging.getLogger(__name__)


def schlick_scale(magnitude, fresnel, f0) -> np.ndarray:
    """Factor multiplying ``E(M^-1 P)`` for Schlick Fresnel with reflectance ``f0``.

    Heitz et al. 2016 (``equations.md`` 2): ``F0 (n - f5) + f5``; broadcasts (e.g. RGB ``f0``).
    """
    f0 = as_unit_interval(f0, "f0")
    magnitude = as_float_array(magnitude, "magnitude")
    fresnel = as_float_array(fresnel, "fresnel")
    broadcast_batch(f0=f0.shape, magnitude=magnitude.shape, fresnel=fresnel.shape)
    return f0 * (magnitude - fresnel) + fresnel


class GGXTable:
    """LTC fit of the isotropic GGX lobe over ``t = sqrt(1 - cos theta)`` and ``r = sqrt(alpha)``.

    Attributes
    ----------
    axis_t : (T,) increasing, ``axis_t[0] = 0`` (normal view); views beyond ``axis_t[-1]`` clamp.
    axis_r : (R,) increasing ``sqrt(alpha)``; ``axis_r[-1] = 1``.
    M : (T, R, 3, 3) LTC matrices in the view's azimuthal frame (view in the xz plane), each
        divided by the length of its third column.
    magnitude, fresnel : (T, R) ``n`` and ``f5``.
    settings : dict of the fit settings the table was baked with.
    path : the file it was loaded from (``None`` when built in memory); source : ``"shipped"``
        (the package's table), ``"user"`` (baked into the user data folder) or ``"file"``.
    """

    path: Path | None = None
    source: str = "memory"

    def __init__(self, axis_t, axis_r, M, magnitude, fresnel, settings=None, fit_error=None):
        self.axis_t = np.asarray(axis_t, dtype=np.float64)
        self.axis_r = np.asarray(axis_r, dtype=np.float64)
        self.M = np.asarray(M, dtype=np.float64)
        self.magnitude = np.asarray(magnitude, dtype=np.float64)
        self.fresnel = np.asarray(fresnel, dtype=np.float64)
        self.settings = dict(settings or {})
        self.fit_error = None if fit_error is None else np.asarray(fit_error, dtype=np.float64)

    def __repr__(self) -> str:
        return (f"GGXTable(T={len(self.axis_t)}, R={len(self.axis_r)}, "
                f"alpha in [{self.alpha_min:.4g}, 1], "
                f"theta <= {np.degrees(self.theta_max):.3g} deg)")

    @property
    def alpha_min(self) -> float:
        return float(self.axis_r[0] ** 2)

    @property
    def theta_max(self) -> float:
        """Largest tabulated view angle (radians); larger angles use this row."""
        return float(np.arccos(1.0 - self.axis_t[-1] ** 2))

    @classmethod
    def load(cls, path: str | os.PathLike | None = None) -> "GGXTable":
        """Read and validate a table file.

        Default: the user table (``prefilter bake ltc-iso`` without ``-o`` writes it, into
        :func:`prefilter.fileio.user_data_dir`) when it exists, else the table shipped with the
        package; :attr:`path` and :attr:`source` say which, and the logger
        ``prefilter.ltc.table`` reports a user table at INFO level.

        Expected ``.npz`` arrays: ``version`` (int, == 1), ``axis_t`` (T,), ``axis_r`` (R,),
        ``M`` (T, R, 3, 3), ``magnitude`` (T, R), ``fresnel`` (T, R), ``settings`` (JSON string);
        optional ``fit_error`` (T, R); ``__meta__`` (JSON with the SHA-256 of the arrays, see
        :mod:`prefilter.fileio`; required). Raises
        :class:`~prefilter.errors.TableFileError` naming the file and field when the file is
        missing, unreadable, corrupt (checksum), of another version, or has wrong shapes, dtypes
        or non-finite values.
        """
        path = Path(path) if path is not None else default_table_path()
        if not path.is_file():
            raise TableFileError(f"LTC table {path}: file not found (bake it with "
                                 f"`prefilter bake ltc-iso -o {path}`)")
        where = f"LTC table {path}"
        # layout first, checksum last: a malformed file gets the precise message
        raw_data = read_npz(path, "LTC table")
        data = {k: v for k, v in raw_data.items() if k != META_KEY}
        need = ("version", "axis_t", "axis_r", "M", "magnitude", "fresnel", "settings")
        expect_table_header(data, need, where, TABLE_VERSION)
        t = expect_array(data, "axis_t", where, ndim=1)
        r = expect_array(data, "axis_r", where, ndim=1)
        if len(t) < 2 or len(r) < 2:
            raise TableFileError(f"{where}: axis_t, axis_r: expected 1-D arrays of length"
                                 f" >= 2, got shapes {t.shape}, {r.shape}")
        T, R = len(t), len(r)
        expect = {"M": (T, R, 3, 3), "magnitude": (T, R), "fresnel": (T, R)}
        if "fit_error" in data:
            expect["fit_error"] = (T, R)
        for k, shape in expect.items():
            expect_array(data, k, where, shape=shape)
        if not (np.all(np.diff(t) > 0) and np.all(np.diff(r) > 0) and t[0] == 0.0 and t[-1] < 1.0
                and r[0] > 0.0 and abs(r[-1] - 1.0) < 1e-12):
            raise TableFileError(f"{where}: axes: expected increasing axis_t from 0 "
                                 f"(< 1) and axis_r in (0, 1] ending at 1")
        if np.any(np.abs(np.linalg.det(data["M"])) < 1e-300):
            raise TableFileError(f"{where}: M: expected invertible matrices")
        if np.any(data["magnitude"] < 0):
            raise TableFileError(f"{where}: magnitude: expected values >= 0")
        settings = expect_json_object(data, "settings", where)
        verify_npz(path, "LTC table", raw_data, format_version=TABLE_VERSION)
        table = cls(t, r, data["M"], data["magnitude"], data["fresnel"], settings,
                    data.get("fit_error"))
        table.path = path
        table.source = table_source(path, shipped_table_path())
        if table.source == "user":
            _log.info("LTC table: the user table %s (not the shipped one)", path)
        return table

    def _coords(self, wo, alpha, wo_name: str = "wo"):
        wo = as_upper_directions(wo, wo_name)
        # Below the first row the lobe is sharper than any fitted entry; like Heitz et al.'s
        # shaders we clamp to it (a near-mirror lobe's polygon integral barely changes).
        alpha = np.maximum(as_roughness(alpha, "alpha", lo=0.0, hi=1.0), self.alpha_min)
        shape = broadcast_batch(**{wo_name: wo.shape[:-1], "alpha": alpha.shape})
        wo = np.broadcast_to(wo, shape + (3,))
        t = np.sqrt(np.maximum(0.0, 1.0 - wo[..., 2]))
        ft = np.interp(t, self.axis_t, np.arange(len(self.axis_t), dtype=np.float64))
        fr = np.interp(np.sqrt(np.broadcast_to(alpha, shape)), self.axis_r,
                       np.arange(len(self.axis_r), dtype=np.float64))
        return wo, ft, fr

    def _bilinear(self, table, ft, fr):
        i = np.minimum(np.floor(ft).astype(np.intp), len(self.axis_t) - 2)
        j = np.minimum(np.floor(fr).astype(np.intp), len(self.axis_r) - 2)
        a = ft - i
        b = fr - j
        extra = (None,) * (table.ndim - 2)
        a = a[(...,) + extra]
        b = b[(...,) + extra]
        return ((1 - a) * (1 - b) * table[i, j] + a * (1 - b) * table[i + 1, j]
                + (1 - a) * b * table[i, j + 1] + a * b * table[i + 1, j + 1])

    def lookup_canonical(self, wo_z, alpha):
        """Bilinear ``(M, magnitude, fresnel)`` in the view's azimuthal frame (view in xz)."""
        wo_z = as_float_array(wo_z, "wo_z")
        if np.any((wo_z < 0.0) | (wo_z > 1.0)):
            raise PrefilterError(f"wo_z: expected cosines in [0, 1], got range "
                                 f"[{wo_z.min():.4g}, {wo_z.max():.4g}]")
        wo = np.stack([np.sqrt(np.maximum(0.0, 1 - wo_z**2)), np.zeros_like(wo_z), wo_z], -1)
        _, ft, fr = self._coords(wo, alpha, "wo_z")
        return (self._bilinear(self.M, ft, fr), self._bilinear(self.magnitude, ft, fr),
                self._bilinear(self.fresnel, ft, fr))

    def lookup(self, wo, alpha):
        """LTC of the GGX lobe for views ``wo (..., 3)`` (local frame), roughness ``alpha (...)``.

        Bilinear interpolation in ``(sqrt(1 - cos theta), sqrt(alpha))``; views beyond the last
        row's angle use that row, roughness below :attr:`alpha_min` uses the first column. ``M`` is
        returned in the local frame: ``Rz(phi) M Rz(phi)^T``
        with ``phi`` the view's azimuth.

        Returns
        -------
        M : (..., 3, 3), magnitude : (...), fresnel : (...)
        """
        wo, ft, fr = self._coords(wo, alpha)
        M = self._bilinear(self.M, ft, fr)
        phi = np.arctan2(wo[..., 1], wo[..., 0])
        c, s = np.cos(phi), np.sin(phi)
        Rz = np.zeros(phi.shape + (3, 3))
        Rz[..., 0, 0] = c
        Rz[..., 0, 1] = -s
        Rz[..., 1, 0] = s
        Rz[..., 1, 1] = c
        Rz[..., 2, 2] = 1.0
        M = Rz @ M @ np.swapaxes(Rz, -1, -2)
        return M, self._bilinear(self.magnitude, ft, fr), self._bilinear(self.fresnel, ft, fr)


def as_table(table):
    """The table a render method uses for ``RenderSettings.table``: ``None`` -> the shipped
    :class:`GGXTable`, a path (``str`` or ``PathLike``) -> :meth:`GGXTable.load` of it, anything
    else (a table or table-like object with ``lookup``) as it is."""
    if table is None:
        return GGXTable.load()
    if isinstance(table, (str, os.PathLike)):
        return GGXTable.load(table)
    return table


def shipped_table() -> GGXTable:
    """The :class:`GGXTable` shipped with the package, whatever user table exists (the
    ``reference`` method's control variate: its images must not depend on the user's files)."""
    return GGXTable.load(shipped_table_path())
