"""LEADR map files: levels and index written as one unit, checksums required."""

from __future__ import annotations

import json

import numpy as np
import pytest

from prefilter.errors import TableFileError
from prefilter.leadr import io as leadr_io
from prefilter.leadr.io import read_maps, write_maps
from prefilter.leadr.maps import moments


def _maps(seed: int):
    return moments(np.random.default_rng(seed).normal(size=(8, 8)), 1.0, 0.05)


def test_write_read_round_trip(tmp_path):
    m = _maps(0)
    write_maps(m, tmp_path)
    levels, info = read_maps(tmp_path)
    assert len(levels) == len(m.chain.levels)
    np.testing.assert_allclose(levels[0], m.chain.levels[0], rtol=1e-6, atol=1e-7)


def test_bake_killed_before_its_index_keeps_the_previous_maps(tmp_path, monkeypatch):
    write_maps(_maps(0), tmp_path)
    old, _ = read_maps(tmp_path)

    def killed(path, obj):  # the process dies after the new levels, before the new index
        raise KeyboardInterrupt

    monkeypatch.setattr(leadr_io, "save_json_atomic", killed)
    with pytest.raises(KeyboardInterrupt):
        write_maps(_maps(1), tmp_path)
    levels, _ = read_maps(tmp_path)
    for a, b in zip(levels, old):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("where", ["index", "level"])
def test_missing_checksum_is_an_error(tmp_path, where):
    write_maps(_maps(0), tmp_path)
    index = (tmp_path / "leadr.json").resolve()
    info = json.loads(index.read_text())
    if where == "index":
        del info["meta_sha256"]
    else:
        del info["levels"][0]["sha256"]
        info.pop("meta_sha256")
        info["meta_sha256"] = leadr_io.json_digest(info)
    index.unlink()
    index.write_text(json.dumps(info))
    with pytest.raises(TableFileError, match="missing checksum"):
        read_maps(tmp_path)
