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
