"""A bake's uncompressed pyramid level on disk: a float32 (or float16) ``.npy`` of NDF images
``(ny, nx, R, R)`` read and written by rows of centres with ``pread`` / ``pwrite``.

A memory map of a level (4.3 GB at level 0 of a 256^2 map with 512^2 images) counts every page
the bake touched in its resident memory until the map is closed; file I/O keeps the bake's memory
at the rows it holds (the page cache is the kernel's to reclaim).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


class LevelFile:
    """The images of one pyramid level in the ``.npy`` file ``path`` (created, or reopened when
    its header matches ``shape`` and ``dtype``: a resumed bake keeps the rows its checkpoints
    mark done). ``dtype``: float32 (levels) or float16 (images stored over their peaks,
    :func:`over_peaks`: the one-pass bake's waiting cells of fitted levels and the images only the
    level difference reads)."""

    def __init__(self, path: str | os.PathLike, shape: tuple[int, ...], dtype=np.float32):
        self.path = Path(path)
        self.shape = tuple(int(n) for n in shape)
        self.dtype = np.dtype(dtype)
        self.item = self.dtype.itemsize
        self.row_items = int(np.prod(self.shape[1:]))
        self.image_items = int(np.prod(self.shape[2:]))
        self.offset = self._reopen()
        if self.offset is None:
            self.offset = self._create()

    def _reopen(self):
        try:
            with open(self.path, "rb") as fh:
                version = np.lib.format.read_magic(fh)
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, fortran, dtype = read_header(fh)
                offset = fh.tell()
        except (OSError, ValueError, EOFError):
            return None  # missing, or killed while the file was being created
        if shape != self.shape or fortran or dtype != self.dtype:
            return None
        if self.path.stat().st_size != offset + self.item * self.row_items * self.shape[0]:
            return None
        return offset

    def _create(self) -> int:
        header = {"descr": np.lib.format.dtype_to_descr(self.dtype),
                  "fortran_order": False, "shape": self.shape}
        with open(self.path, "wb") as fh:
            np.lib.format.write_array_header_1_0(fh, header)
            offset = fh.tell()
            fh.truncate(offset + self.item * self.row_items * self.shape[0])  # sparse until written
        return offset

    def write_rows(self, y0: int, images: np.ndarray) -> None:
        """Write rows ``y0 ..`` of centres: ``images (n, nx, R, R)``."""
        data = np.ascontiguousarray(images, dtype=self.dtype)
        fd = os.open(self.path, os.O_WRONLY)
        try:
            view, pos = memoryview(data).cast("B"), self.offset + self.item * self.row_items * y0
            while view.nbytes:
                n = os.pwrite(fd, view, pos)
                view, pos = view[n:], pos + n
        finally:
            os.close(fd)

    def write_columns(self, y: int, x0: int, images: np.ndarray) -> None:
        """Write images ``(n, R, R)`` at row ``y``, columns ``x0 .. x0 + n - 1``."""
        data = np.ascontiguousarray(images, dtype=self.dtype)
        fd = os.open(self.path, os.O_WRONLY)
        try:
            view = memoryview(data).cast("B")
            pos = self.offset + self.item * (self.row_items * y + self.image_items * x0)
            while view.nbytes:
                n = os.pwrite(fd, view, pos)
                view, pos = view[n:], pos + n
        finally:
            os.close(fd)

    def read_periodic(self, y: int, x0: int, n: int) -> np.ndarray:
        """Images ``(n, R, R)`` of row ``y``, columns ``x0, x0 + 1, ..`` modulo the level's
        width (the pyramid is periodic)."""
        nx = self.shape[1]
        cols = (x0 + np.arange(n)) % nx
        # runs of consecutive columns, each one read
        cuts = np.flatnonzero(np.diff(cols) != 1) + 1
        return np.concatenate([self.read(y, y + 1, int(r[0]), int(r[-1]) + 1)[0]
                               for r in np.split(cols, cuts)])

    def read(self, y0: int, y1: int, x0: int = 0, x1: int | None = None,
             step: int = 1) -> np.ndarray:
        """Images ``(y1 - y0, len(range(x0, x1, step)), R, R)`` (the file's dtype) of rows
        ``y0 .. y1 - 1`` and columns ``x0, x0 + step, .. < x1`` (a copy)."""
        x1 = self.shape[1] if x1 is None else x1
        xs = range(x0, x1, step)
        out = np.empty((y1 - y0, len(xs)) + self.shape[2:], self.dtype)
        fd = os.open(self.path, os.O_RDONLY)
        try:
            for i, y in enumerate(range(y0, y1)):
                row = self.offset + self.item * self.row_items * y
                # contiguous columns in one read, strided ones image by image
                runs = ([(x0, out[i])] if step == 1 else
                        [(x, out[i, k]) for k, x in enumerate(xs)])
                for x, buf in runs:
                    view, pos = memoryview(buf).cast("B"), row + self.item * self.image_items * x
                    while view.nbytes:
                        n = os.preadv(fd, [view], pos)
                        if n == 0:
                            raise EOFError(f"{self.path}: truncated level file")
                        view, pos = view[n:], pos + n
        finally:
            os.close(fd)
        return out


def over_peaks(images: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``images (..., R, R)`` divided by their peaks, and the peaks ``(...)`` float32 (1 for
    blank images): what float16 level files hold, so that no image overflows float16 and each
    keeps its relative rounding (5e-4)."""
    peak = np.asarray(images).max(axis=(-2, -1))
    peak = np.where(peak > 0, peak, 1.0).astype(np.float32)
    return images / peak[..., None, None], peak
