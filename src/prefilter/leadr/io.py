"""EXR files of LEADR moment maps for engines.

One file per mip level, ``leadr_L{level}.exr``, float32, ZIP, five named channels
``E_x, E_y, E_xx, E_yy, E_xy`` (:data:`prefilter.leadr.maps.CHANNELS`) and the checksum attribute
``prefilter_sha256`` (:mod:`prefilter.texture.io`), plus ``leadr.json`` with the format name and
version, the slope convention, the base roughness and, per level, its file, shape and the SHA-256
of its channels, and ``meta_sha256``, the SHA-256 of all its other fields. :func:`read_maps`
checks all of it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from prefilter.fileio import (
    array_digest,
    atomic_file_set,
    atomic_path,
    json_digest,
    save_json_atomic,
)
from prefilter.errors import PrefilterError, TableFileError
from prefilter.leadr.maps import CHANNELS, LeadrMaps
from prefilter.texture.io import read_exr_channels, write_exr_channels

FORMAT = "prefilter-leadr"
VERSION = 1

CONVENTION = ("slope s = grad h = (dh/dx, dh/dy) = (-n_x/n_z, -n_y/n_z); x along columns (u), "
              "y along rows (v); covariance = [E[ss^T] - E[s]E[s]^T]_+ + base_roughness^2 I")


def _channels(level: np.ndarray) -> dict[str, np.ndarray]:
    a = np.asarray(level, dtype=np.float64)
    if a.ndim != 3 or a.shape[2] != len(CHANNELS):
        raise PrefilterError(f"level: expected shape (H, W, 5), got {a.shape}")
    return {n: np.ascontiguousarray(a[..., i], dtype=np.float32) for i, n in enumerate(CHANNELS)}


def write_moment_exr(path, level: np.ndarray) -> Path:
    """Write one ``(H, W, 5)`` moment level as an EXR with channels :data:`CHANNELS`."""
    chans = _channels(level)
    path = Path(path)
    with atomic_path(path, suffix=".exr") as tmp:
        write_exr_channels(tmp, chans)
    return path


def read_moment_exr(path) -> np.ndarray:
    """Read an EXR written by :func:`write_moment_exr` as ``(H, W, 5)`` float64 (checksum
    required and verified)."""
    path = Path(path)
    if not path.is_file():
        raise TableFileError(f"{path}: moment map not found")
    ch = read_exr_channels(path, require_checksum=True)
    missing = [n for n in CHANNELS if n not in ch]
    if missing:
        raise TableFileError(f"{path}: expected channels {', '.join(CHANNELS)}; missing {missing}")
    if len({ch[n].shape for n in CHANNELS}) != 1:
        raise TableFileError(f"{path}: expected channels of one shape, got "
                             f"{[ch[n].shape for n in CHANNELS]}")
    return np.stack([ch[n].astype(np.float64) for n in CHANNELS], axis=-1)


def write_maps(maps: LeadrMaps, out_dir, *, all_levels: bool = True, meta: dict | None = None):
    """Write ``leadr_L{l}.exr`` for every level (or level 0 only) and ``leadr.json`` as one unit
    (:func:`~prefilter.fileio.atomic_file_set`): a bake killed at any moment leaves the previous
    maps or the new ones, never new levels beside an old index."""
    out = Path(out_dir)
    levels = maps.chain.levels if all_levels else maps.chain.levels[:1]
    names = ["leadr.json"] + [f"leadr_L{i}.exr" for i in range(len(levels))]
    with atomic_file_set([out / n for n in names]) as paths:
        entries = []
        for lv, path in zip(levels, paths[1:]):
            write_moment_exr(path, lv)
            entries.append({"file": path.name, "shape": list(lv.shape[:2]),
                            "sha256": array_digest(_channels(lv))})
        info = {
            "format": FORMAT,
            "version": VERSION,
            "channels": list(CHANNELS),
            "convention": CONVENTION,
            "base_roughness": maps.base_roughness,
            "levels": entries,
            "mip_filter": "2x2 box average of the level above (moments are linear)",
        }
        info.update(meta or {})
        info["meta_sha256"] = json_digest(info)
        save_json_atomic(paths[0], info)
    return [out / e["file"] for e in entries]


def read_maps(out_dir) -> tuple[list[np.ndarray], dict]:
    """The moment levels ``(H_l, W_l, 5)`` float64 and the ``leadr.json`` index of a baked
    directory, every field and checksum verified (:class:`~prefilter.errors.TableFileError`
    naming the file and field otherwise)."""
    index = Path(out_dir) / "leadr.json"
    if not index.is_file():
        raise TableFileError(f"{index}: LEADR index not found (bake it with "
                             f"`prefilter bake leadr HEIGHT -o {index.parent}`)")
    # the levels are read beside the resolved index, so a bake switching versions meanwhile
    # cannot mix two bakes' files
    index = index.resolve()
    out = index.parent
    try:
        info = json.loads(index.read_text())
    except (ValueError, OSError) as exc:  # JSON and Unicode errors are ValueErrors
        raise TableFileError(f"{index}: unreadable JSON ({type(exc).__name__}: {exc})") from None
    if not isinstance(info, dict):
        raise TableFileError(f"{index}: expected a JSON object, got {type(info).__name__}")
    if "meta_sha256" not in info:
        raise TableFileError(f"{index}: meta_sha256: missing checksum (the index was edited or "
                             f"not written by prefilter)")
    want = info.pop("meta_sha256")
    if json_digest(info) != want:
        raise TableFileError(f"{index}: meta_sha256: checksum mismatch (expected {want!r}): "
                             f"the index is corrupt or was edited")
    if info.get("format", FORMAT) != FORMAT:
        raise TableFileError(f"{index}: format: expected {FORMAT!r}, got {info.get('format')!r}")
    if info.get("version", VERSION) != VERSION:
        raise TableFileError(f"{index}: version: expected {VERSION}, got {info.get('version')!r}")
    if info.get("channels") != list(CHANNELS):
        raise TableFileError(f"{index}: channels: expected {list(CHANNELS)}, got "
                             f"{info.get('channels')!r}")
    br = info.get("base_roughness")
    if isinstance(br, bool) or not isinstance(br, (int, float)) or not np.isfinite(br) or br < 0:
        raise TableFileError(f"{index}: base_roughness: expected a number >= 0, got {br!r}")
    entries = info.get("levels")
    if not isinstance(entries, list) or not entries:
        raise TableFileError(f"{index}: levels: expected a non-empty list, got {entries!r}")
    levels = []
    for i, e in enumerate(entries):
        at = f"{index}: levels[{i}]"
        if not (isinstance(e, dict) and isinstance(e.get("file"), str)
                and isinstance(e.get("shape"), list)):
            raise TableFileError(f"{at}: expected {{'file': str, 'shape': [H, W], 'sha256': str}}"
                                 f", got {e!r}")
        f = out / e["file"]
        if Path(e["file"]).name != e["file"]:
            raise TableFileError(f"{at}.file: expected a file name in {out}, got {e['file']!r}")
        lv = read_moment_exr(f)
        if list(lv.shape[:2]) != e["shape"]:
            raise TableFileError(f"{f}: shape: expected {e['shape']} (leadr.json), got "
                                 f"{list(lv.shape[:2])}")
        if "sha256" not in e:
            raise TableFileError(f"{at}.sha256: missing checksum (the index was edited or not "
                                 f"written by prefilter)")
        if array_digest(_channels(lv)) != e["sha256"]:
            raise TableFileError(f"{f}: sha256: checksum mismatch with {index.name} (expected "
                                 f"{e['sha256']}): the file is corrupt or from another bake")
        levels.append(lv)
    return levels, info
