"""EXR files of LEADR moment maps for engines.

One file per mip level, ``leadr_L{level}.exr``, float32, ZIP, five named channels
``E_x, E_y, E_xx, E_yy, E_xy`` (:data:`prefilter.leadr.maps.CHANNELS`), plus ``leadr.json`` with
the slope convention, the base roughness and the level shapes.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from prefilter._io import atomic_path, save_json_atomic
from prefilter.errors import PrefilterError
from prefilter.leadr.maps import CHANNELS, LeadrMaps

CONVENTION = ("slope s = grad h = (dh/dx, dh/dy) = (-n_x/n_z, -n_y/n_z); x along columns (u), "
              "y along rows (v); covariance = [E[ss^T] - E[s]E[s]^T]_+ + base_roughness^2 I")


def write_moment_exr(path, level: np.ndarray) -> Path:
    """Write one ``(H, W, 5)`` moment level as an EXR with channels :data:`CHANNELS`."""
    import OpenEXR

    a = np.asarray(level, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != len(CHANNELS):
        raise PrefilterError(f"level: expected shape (H, W, 5), got {a.shape}")
    chans = {n: np.ascontiguousarray(a[..., i], dtype=np.float32) for i, n in enumerate(CHANNELS)}
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    path = Path(path)
    with atomic_path(path, suffix=".exr") as tmp:
        with OpenEXR.File(header, chans) as f:
            f.write(str(tmp))
    return path


def read_moment_exr(path) -> np.ndarray:
    """Read an EXR written by :func:`write_moment_exr` as ``(H, W, 5)`` float64."""
    import OpenEXR

    path = Path(path)
    if not path.is_file():
        raise PrefilterError(f"{path}: moment map not found")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.asarray(v.pixels, np.float64) for k, v in f.channels().items()}
    except (RuntimeError, OSError) as exc:
        raise PrefilterError(f"{path}: unreadable or corrupt EXR ({exc})") from None
    missing = [n for n in CHANNELS if n not in ch]
    if missing:
        raise PrefilterError(f"{path}: expected channels {', '.join(CHANNELS)}; missing {missing}")
    return np.stack([ch[n] for n in CHANNELS], axis=-1)


def write_maps(maps: LeadrMaps, out_dir, *, all_levels: bool = True, meta: dict | None = None):
    """Write ``leadr_L{l}.exr`` for every level (or level 0 only) and ``leadr.json``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    levels = maps.chain.levels if all_levels else maps.chain.levels[:1]
    files = [write_moment_exr(out / f"leadr_L{i}.exr", lv).name for i, lv in enumerate(levels)]
    info = {
        "channels": list(CHANNELS),
        "convention": CONVENTION,
        "base_roughness": maps.base_roughness,
        "levels": [{"file": f, "shape": list(lv.shape[:2])} for f, lv in zip(files, levels)],
        "mip_filter": "2x2 box average of the level above (moments are linear)",
    }
    info.update(meta or {})
    save_json_atomic(out / "leadr.json", info)
    return [out / f for f in files]
