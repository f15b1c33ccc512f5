"""The anisotropic GGX LTC table: file layout, validation and quadrilinear lookup.

Anisotropic-LTC paper, sections 6-9: one aligned LTC matrix ``M`` (stored, not ``M^-1``; divided by
the length of its third column), a magnitude ``n`` and a Fresnel scalar ``f5`` per entry of a 4D
grid over the view angle ``theta``, the view azimuth ``phi in [0, pi/2]`` (relative to the
tangent), the larger roughness ``alpha`` and the ratio ``r = min / max`` of the two roughnesses.
Lookup folds any configuration into that domain with the symmetries of :mod:`.symmetry`,
interpolates the aligned matrices quadrilinearly and maps the result back.

Interpolation coordinates: ``theta`` and ``phi`` linear, ``sqrt(alpha)`` and ``sqrt(r)`` (nodes are
uniform in these coordinates for tables baked here; any increasing nodes are accepted).
Coordinates outside the grid clamp to its border.
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np

from prefilter.fileio import (META_KEY, expect_array, expect_json_object, expect_table_header,
                           read_npz, save_npz_atomic, table_source, user_data_dir, verify_npz)
from prefilter.validation import as_roughness, as_upper_directions
from prefilter.errors import PrefilterError, TableFileError
from prefilter.ltc.aniso import symmetry

#: Version of the file layout written by :meth:`AnisoGGXTable.save`.
TABLE_VERSION = 1
#: Format name recorded in the file's ``__meta__`` checksum entry.
FORMAT = "prefilter-ltc-aniso"

AXES = ("axis_theta", "axis_phi", "axis_alpha", "axis_ratio")


#: File name of the table, in the package data and in the user data folder.
TABLE_NAME = "ggx_aniso.npz"

_log = logging.getLogger(__name__)


def shipped_table_path() -> Path:
    """The table shipped with the package (``prefilter/ltc/data/ggx_aniso.npz``)."""
    return Path(__file__).resolve().parent.parent / "data" / TABLE_NAME


def user_table_path() -> Path:
    """Where ``prefilter bake ltc-aniso`` writes without ``-o``:
    :func:`prefilter.fileio.user_data_dir` ``/ ggx_aniso.npz``."""
    return user_data_dir() / TABLE_NAME


def default_table_path() -> Path:
    """The table ``AnisoGGXTable.load()`` reads: the user table when one was baked, else the
    shipped one."""
    user = user_table_path()
    return user if user.is_file() else shipped_table_path()


def _coord(name, x):
    """Interpolation coordinate of axis ``name`` for values ``x``."""
    return np.sqrt(x) if name in ("axis_alpha", "axis_ratio") else np.asarray(x, float)


class AnisoGGXTable:
    """LTC fit of anisotropic GGX over ``(theta, phi, alpha, ratio)``.

    Attributes
    ----------
    axis_theta, axis_phi, axis_alpha, axis_ratio : increasing node values (radians for angles).
        ``axis_theta[0] = 0``, ``axis_phi = [0 .. pi/2]`` symmetric about ``pi/4``,
        ``axis_alpha[-1] = axis_ratio[-1] = 1``.
    M : (T, F, A, R, 3, 3) aligned matrices with unit third column (view in the tangent frame,
        ``GGX(alpha, alpha * ratio)``, ``v_x, v_y >= 0``).
    magnitude, fresnel : (T, F, A, R) ``n`` and ``f5`` (Hill and Heitz 2016).
    settings : dict, how the table was baked. diagnostics : dict of per-entry arrays (optional).
    path : the file it was loaded from (``None`` when built in memory); source : ``"shipped"``,
        ``"user"`` (baked into the user data folder) or ``"file"``.
    """

    path: Path | None = None
    source: str = "memory"

    def __init__(self, axes, M, magnitude, fresnel, settings=None, diagnostics=None):
        for name, a in zip(AXES, axes):
            setattr(self, name, np.asarray(a, dtype=np.float64))
        self.M = np.asarray(M, dtype=np.float64)
        self.magnitude = np.asarray(magnitude, dtype=np.float64)
        self.fresnel = np.asarray(fresnel, dtype=np.float64)
        self.settings = dict(settings or {})
        self.diagnostics = dict(diagnostics or {})
        self._coords = [_coord(n, getattr(self, n)) for n in AXES]

    @property
    def axes(self) -> tuple[np.ndarray, ...]:
        return tuple(getattr(self, n) for n in AXES)

    @property
    def shape(self) -> tuple[int, ...]:
        return self.M.shape[:4]

    def __repr__(self) -> str:
        return (f"AnisoGGXTable(shape={self.shape}, alpha in [{self.axis_alpha[0]:.3g}, 1], "
                f"ratio in [{self.axis_ratio[0]:.3g}, 1], theta <= "
                f"{np.degrees(self.axis_theta[-1]):.3g} deg)")

    # -- file ------------------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write the ``.npz`` layout documented in :meth:`load` (atomically)."""
        extra = {f"diag_{k}": np.asarray(v) for k, v in self.diagnostics.items()}
        save_npz_atomic(path, format_name=FORMAT, format_version=TABLE_VERSION,
                        version=np.int64(TABLE_VERSION),
                        **{n: getattr(self, n) for n in AXES}, M=self.M,
                        magnitude=self.magnitude, fresnel=self.fresnel,
                        settings=np.array(json.dumps(self.settings, sort_keys=True)), **extra)

    @classmethod
    def load(cls, path: str | os.PathLike | None = None) -> "AnisoGGXTable":
        """Read and validate a table.

        Default: the user table (``prefilter bake ltc-aniso`` without ``-o`` writes it, into
        :func:`prefilter.fileio.user_data_dir`) when it exists, else the one shipped with the
        package; :attr:`path` and :attr:`source` say which, and the logger
        ``prefilter.ltc.aniso.table`` reports a user table at INFO level.

        ``.npz`` arrays: ``version`` (== 1), ``axis_theta`` (T,), ``axis_phi`` (F,),
        ``axis_alpha`` (A,), ``axis_ratio`` (R,), ``M`` (T, F, A, R, 3, 3), ``magnitude`` and
        ``fresnel`` (T, F, A, R), ``settings`` (JSON string); optional ``diag_*`` arrays;
        ``__meta__`` (format, version and SHA-256 of the arrays, :mod:`prefilter.fileio`;
        required). Raises :class:`~prefilter.errors.TableFileError` naming the file and
        field for missing, corrupt (checksum), unknown-version or malformed files.
        """
        path = Path(path) if path is not None else default_table_path()
        if not path.is_file():
            raise TableFileError(f"anisotropic LTC table {path}: file not found (bake it with "
                                 f"`prefilter bake ltc-aniso -o {path}`)")
        where = f"anisotropic LTC table {path}"
        # layout first, checksum last: a malformed file gets the precise message
        raw_data = read_npz(path, "anisotropic LTC table")
        data = {k: v for k, v in raw_data.items() if k != META_KEY}
        need = ("version", *AXES, "M", "magnitude", "fresnel", "settings")
        expect_table_header(data, need, where, TABLE_VERSION)
        axes = [expect_array(data, n, where, ndim=1) for n in AXES]
        if any(len(a) < 2 or not np.all(np.diff(a) > 0) for a in axes):
            raise TableFileError(f"{where}: axes: expected increasing 1-D arrays of length >= 2, "
                                 f"got lengths {[len(a) for a in axes]}")
        shape = tuple(len(a) for a in axes)
        for k, s in (("M", shape + (3, 3)), ("magnitude", shape), ("fresnel", shape)):
            expect_array(data, k, where, shape=s)
        th, ph, al, ra = axes
        if not (th[0] == 0 and th[-1] < np.pi / 2 and abs(ph[0]) < 1e-12
                and abs(ph[-1] - np.pi / 2) < 1e-12 and al[0] > 0 and abs(al[-1] - 1) < 1e-12
                and ra[0] > 0 and abs(ra[-1] - 1) < 1e-12):
            raise TableFileError(f"{where}: axes: expected theta from 0, "
                                 f"phi over [0, pi/2], alpha and ratio in (0, 1] ending at 1")
        if np.any(np.linalg.det(data["M"]) <= 0):
            raise TableFileError(f"{where}: M: expected positive determinants")
        if np.any(data["magnitude"] < 0):
            raise TableFileError(f"{where}: magnitude: expected values >= 0")
        settings = expect_json_object(data, "settings", where)
        unknown = [k for k in data if k not in need and not k.startswith("diag_")]
        if unknown:
            raise TableFileError(f"{where}: unknown arrays {unknown}; expected {list(need)} "
                                 f"and diag_*")
        verify_npz(path, "anisotropic LTC table", raw_data, format_name=FORMAT,
                   format_version=TABLE_VERSION)
        diagnostics = {k[5:]: data[k] for k in data if k.startswith("diag_")}
        table = cls(axes, data["M"], data["magnitude"], data["fresnel"], settings, diagnostics)
        table.path = path
        table.source = table_source(path, shipped_table_path())
        if table.source == "user":
            _log.info("anisotropic LTC table: the user table %s (not the shipped one)", path)
        return table

    # -- lookup ----------------------------------------------------------------------------------
    def fractional_index(self, v, alpha, ratio):
        """Fractional grid coordinates ``(..., 4)`` of folded configurations (clamped)."""
        theta = np.arccos(np.clip(v[..., 2], -1.0, 1.0))
        phi = np.arctan2(v[..., 1], v[..., 0])
        vals = (theta, phi, alpha, ratio)
        return np.stack([np.interp(_coord(n, x), c, np.arange(len(c), dtype=np.float64))
                         for n, x, c in zip(AXES, vals, self._coords)], -1)

    def interpolate(self, table, f):
        """Quadrilinear interpolation of ``table (T, F, A, R, ...)`` at fractions ``f (..., 4)``."""
        shape = self.shape
        i0 = [np.minimum(np.floor(f[..., k]).astype(np.intp), shape[k] - 2) for k in range(4)]
        t = [f[..., k] - i0[k] for k in range(4)]
        trailing = table.shape[4:]
        flat = table.reshape((-1,) + trailing)
        strides = np.cumprod((1,) + shape[:0:-1])[::-1]  # row-major strides of the 4 axes
        base = sum(i0[k] * strides[k] for k in range(4))
        extra = (None,) * len(trailing)
        out = 0.0
        for corner in range(16):
            b = [(corner >> k) & 1 for k in range(4)]
            w = np.ones_like(t[0])
            for k in range(4):
                w = w * (t[k] if b[k] else 1.0 - t[k])
            off = int(sum(b[k] * strides[k] for k in range(4)))
            out = out + w[(...,) + extra] * flat[base + off]
        return out

    def lookup_canonical(self, v, alpha, ratio):
        """Interpolated ``(M, magnitude, fresnel)`` for folded configurations (no symmetry)."""
        f = self.fractional_index(np.asarray(v, float), np.asarray(alpha, float),
                                  np.asarray(ratio, float))
        if getattr(self, "_packed", None) is None:
            # one gather per corner for all 11 numbers (M, n, f5)
            self._packed = np.concatenate([self.M.reshape(self.shape + (9,)),
                                           self.magnitude[..., None], self.fresnel[..., None]], -1)
        x = self.interpolate(self._packed, f)
        return x[..., :9].reshape(x.shape[:-1] + (3, 3)), x[..., 9], x[..., 10]

    def lookup(self, wo, alpha_x, alpha_y):
        """LTC of the GGX(alpha_x, alpha_y) lobe seen from ``wo``.

        Parameters
        ----------
        wo : (..., 3) unit views above the surface in the tangent frame (x = tangent).
        alpha_x, alpha_y : (...) roughness along the tangent and the bitangent.

        Returns
        -------
        M : (..., 3, 3) LTC matrix in the tangent frame (positive determinant; invert it or pass
            it to :func:`~prefilter.sphere.polygon.polygon_integral`), magnitude : (...),
            fresnel : (...).
            Configurations outside the table's ranges use the nearest border entry.
        """
        wo = as_upper_directions(wo, "wo")
        ax = as_roughness(alpha_x, "alpha_x")
        ay = as_roughness(alpha_y, "alpha_y")
        try:
            shape = np.broadcast_shapes(wo.shape[:-1], ax.shape, ay.shape)
        except ValueError:
            raise PrefilterError(f"wo, alpha_x, alpha_y: batch shapes {wo.shape[:-1]}, "
                                 f"{ax.shape}, {ay.shape} do not broadcast") from None
        wo = np.broadcast_to(wo, shape + (3,))
        v, alpha, ratio, swap, sx, sy = symmetry.canonical_view(
            wo, np.broadcast_to(ax, shape), np.broadcast_to(ay, shape))
        M, mag, fr = self.lookup_canonical(v, alpha, ratio)
        return symmetry.unfold(M, swap, sx, sy), mag, fr

    def shade(self, wo, alpha_x, alpha_y, vertices, *, two_sided: bool = False):
        """``magnitude * polygon_integral(M, vertices)`` (Fresnel 1), batch dims broadcast."""
        from prefilter.sphere.polygon import polygon_integral

        M, mag, _ = self.lookup(wo, alpha_x, alpha_y)
        return mag * polygon_integral(M, vertices, two_sided=two_sided)
