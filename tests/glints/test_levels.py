"""The bake's level files: rows written and read back by file I/O, reopened when resumed."""

import numpy as np

from prefilter.glints.levels import LevelFile


def test_rows_round_trip_and_strided_columns(tmp_path):
    rng = np.random.default_rng(0)
    data = rng.random((4, 6, 3, 3)).astype(np.float32)
    f = LevelFile(tmp_path / "l.npy", data.shape)
    for y in (2, 0, 3, 1):
        f.write_rows(y, data[y:y + 1])
    np.testing.assert_array_equal(f.read(0, 4), data)
    np.testing.assert_array_equal(f.read(1, 3, 2, 5), data[1:3, 2:5])
    np.testing.assert_array_equal(f.read(2, 3, step=2), data[2:3, ::2])
    # a plain .npy: NumPy reads what the bake wrote
    np.testing.assert_array_equal(np.load(tmp_path / "l.npy"), data)


def test_reopened_when_the_shape_matches_else_recreated(tmp_path):
    data = np.arange(2 * 2 * 2 * 2, dtype=np.float32).reshape(2, 2, 2, 2)
    LevelFile(tmp_path / "l.npy", data.shape).write_rows(0, data)
    np.testing.assert_array_equal(LevelFile(tmp_path / "l.npy", data.shape).read(0, 2), data)
    again = LevelFile(tmp_path / "l.npy", (2, 2, 2, 3))
    assert again.read(0, 2).shape == (2, 2, 2, 3)
    (tmp_path / "l.npy").write_bytes(b"\x93NUMPY")  # killed while being created
    LevelFile(tmp_path / "l.npy", data.shape).write_rows(0, data)
    np.testing.assert_array_equal(np.load(tmp_path / "l.npy"), data)


def test_float16_level_file_over_peaks_round_trips(tmp_path):
    """Images over their peaks in a float16 LevelFile come back within float16's relative
    rounding of each image's peak, also where the raw values would overflow float16."""
    from prefilter.glints.levels import over_peaks

    rng = np.random.default_rng(0)
    imgs = rng.random((2, 3, 8, 8)) * np.array([1e-3, 1.0, 1e6])[None, :, None, None]
    imgs[1, 2] = 0.0  # a blank image: peak 1
    f = LevelFile(tmp_path / "h.npy", (2, 3, 8, 8), np.float16)
    p = LevelFile(tmp_path / "p.npy", (2, 3))
    scaled, peak = over_peaks(imgs)
    f.write_rows(0, scaled)
    p.write_rows(0, peak)
    back = f.read(0, 2).astype(np.float32) * p.read(0, 2)[..., None, None]
    assert f.read(0, 1).dtype == np.float16 and peak[1, 2] == 1.0
    err = np.abs(back - imgs).max(axis=(-2, -1)) / np.maximum(imgs.max(axis=(-2, -1)), 1e-300)
    assert np.all(np.isfinite(back)) and err.max() < 1e-3
    assert LevelFile(tmp_path / "h.npy", (2, 3, 8, 8)).read(0, 1).dtype == np.float32  # recreated
