"""A render cut into bands of image rows, each an independent task.

Every image row draws its random numbers from its own generator (the driver's ``row_rng``, the
reference's per-pixel scrambles), so a band of rows rendered alone is those rows of the whole
image, byte for byte. :func:`render_tiled` renders the bands as tasks of
:class:`prefilter.distributed.Engine` (this process, a local cluster or a Dask cluster) and
checkpoints each finished band beside the output (``<out>.parts/``), so a killed reference render
of thousands of samples per pixel resumes where it stopped.
"""

from __future__ import annotations

import hashlib
import json
import os
import pickle
from pathlib import Path

import numpy as np

from prefilter.distributed import Engine
from prefilter.errors import PrefilterError
from prefilter.fileio import Checkpoints
from prefilter.render.driver import render
from prefilter.render.scene import Scene, load_scene
from prefilter.texture.io import write_image
from prefilter.validation import as_positive_int

#: Image rows per band when the caller does not choose.
TILE_ROWS = 16

__all__ = ["TILE_ROWS", "render_band", "render_tiled", "tile_bounds"]


def tile_bounds(height: int, tile_rows: int) -> list[tuple[int, int]]:
    """Row ranges ``[(r0, r1), ...]`` of ``tile_rows`` rows covering ``height`` rows."""
    return [(r0, min(height, r0 + tile_rows)) for r0 in range(0, height, tile_rows)]


def render_band(scene: Scene, method: str, rows: tuple[int, int], spp: int, seed: int,
                jitter: tuple[float, float], table, params: dict,
                chunk_samples: int) -> dict[str, np.ndarray]:
    """One task: ``{"image": (r1 - r0, W, 3) float32}``, the rows ``rows`` of the render."""
    return {"image": render(scene, method, spp=spp, seed=seed, jitter=jitter, table=table,
                            params=params, chunk_samples=chunk_samples, rows=rows)}


def _scene_digest(scene: Scene) -> str:
    """SHA-256 of the loaded scene (its pickle): checkpoints of another scene are discarded."""
    return hashlib.sha256(pickle.dumps(scene)).hexdigest()


def render_tiled(scene, method: str = "reference", *, out: str | os.PathLike, spp: int = 1,
                 seed: int = 0, jitter=(0.0, 0.0), table=None, params=None,
                 chunk_samples: int = 1 << 18, tile_rows: int = TILE_ROWS,
                 scheduler: str | None = None, workers: int | None = None,
                 progress: bool = False) -> np.ndarray:
    """:func:`prefilter.render.driver.render` by bands of ``tile_rows`` image rows, each a task
    on ``scheduler`` / ``workers`` (:class:`prefilter.distributed.Engine`), written to ``out``
    (EXR or ``.npy``, atomically): the same bytes as one ``render`` call.

    Finished bands are kept in ``<out>.parts/`` until ``out`` is written; a killed render run
    again with the same arguments resumes from them. The scene is sent once to every worker.
    ``table``: a table file or ``None`` (workers load it themselves).

    Returns
    -------
    numpy.ndarray, shape (H, W, 3), float32
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    tile_rows = as_positive_int(tile_rows, "tile_rows")
    if table is not None and not isinstance(table, (str, Path)):
        raise PrefilterError("table: expected a table file or None for a tiled render, got "
                             f"{type(table).__name__}")
    table = None if table is None else str(table)
    params = dict(params or {})
    jitter = (float(jitter[0]), float(jitter[1]))
    bands = tile_bounds(scene.camera.height, tile_rows)
    key = {"format": "render-bands", "scene_sha256": _scene_digest(scene), "method": method,
           "spp": int(spp), "seed": int(seed), "jitter": jitter, "table": table,
           "params": params, "chunk_samples": int(chunk_samples), "tile_rows": tile_rows}
    json.dumps(key)  # the key must be JSON (Checkpoints stores it)
    # the first band in this process: bad arguments fail here, not on a worker
    render(scene, method, spp=spp, seed=seed, jitter=jitter, table=table, params=params,
           chunk_samples=chunk_samples, rows=(0, 1))
    ck = Checkpoints(out, key)
    with Engine(scheduler, workers=workers) as engine:
        shared = engine.scatter(scene)
        engine.run(render_band, [(shared, method, b, spp, seed, jitter, table, params,
                                  chunk_samples) for b in bands], ck, progress=progress,
                   desc=f"{method} bands")
    image = np.concatenate([ck.load(i)["image"] for i in range(len(bands))])
    write_image(out, image)
    ck.clear()
    return image
