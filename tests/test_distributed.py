"""The task engine on a LocalCluster of 2 worker processes: bakes and renders give the bytes of
one process, a worker killed mid-bake changes nothing, a scheduler that does not answer is a
clear error within the timeout, and workers run the package's cached Numba kernels."""

from __future__ import annotations

import math
import os
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pytest

from prefilter.distributed import SYNCHRONOUS, Engine, resolve_scheduler, task_map
from prefilter.errors import PrefilterError
from prefilter.ltc.fit_iso import FitSettings, bake_table

distributed = pytest.importorskip("distributed")

#: A small table: 6 rows of 4 roughnesses (about 0.3 s a row).
SMALL = FitSettings(res_theta=6, res_alpha=4, n_fit=8, quad_nodes=16)


@pytest.fixture(scope="module")
def one_table(tmp_path_factory):
    """The bytes of :data:`SMALL` baked in this process."""
    return bake_table(tmp_path_factory.mktemp("one") / "one.npz", SMALL,
                      progress=False).read_bytes()

#: A small scene lit by one quad light (the fused reference kernel).
SCENE = {
    "camera": {"origin": [0, 1.2, 4], "target": [0, 0, -2], "up": [0, 1, 0], "fov": 40,
               "width": 24, "height": 20},
    "objects": [
        {"type": "plane", "center": [0, 0, -10], "normal": [0, 1, 0], "tangent": [1, 0, 0],
         "size": [20, 30], "uv_scale": [20, 30],
         "material": {"alpha": 0.2, "base_color": 0.1, "f0": 0.5,
                      "normal_map": {"procedural": "gaussian", "size": 32, "seed": 1,
                                     "rms_slope": 0.3, "corr_length": 4}}},
        {"type": "sphere", "center": [0.5, 0.5, -3], "radius": 0.8,
         "material": {"alpha": 0.3, "base_color": [0.2, 0.3, 0.6], "f0": 0.04}},
    ],
    "lights": [{"type": "quad", "vertices": [[-2, 0.5, -8], [2, 0.5, -8], [2, 3, -8],
                                             [-2, 3, -8]], "radiance": [4, 4, 4]}],
}


@pytest.fixture(scope="module")
def cluster():
    """A LocalCluster of 2 worker processes (one thread each), shared by the tests here."""
    import logging

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as c:
        yield c


def _dead_address() -> str:
    """A local TCP address nothing listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return f"tcp://127.0.0.1:{port}"


def test_ltc_table_on_two_workers_is_byte_identical(tmp_path, cluster, one_table):
    two = bake_table(tmp_path / "two.npz", SMALL, progress=False,
                     scheduler=cluster.scheduler_address)
    assert two.read_bytes() == one_table
    assert not (tmp_path / "two.npz.parts").exists()


def test_worker_killed_mid_bake_finishes_byte_identical(tmp_path, one_table):
    import logging

    # a cluster of its own: the kill restarts a worker. The test's own client is closed while the
    # bake's client runs: two clients of one process on different event loops can trip over
    # each other's asyncio objects (distributed's client is not made for that).
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, silence_logs=logging.ERROR) as c:
        with distributed.Client(c) as client:
            victim = next(iter(client.run(os.getpid).values()))
        killed = []

        def kill_once(row):
            if not killed:
                # the other rows are in flight on both workers: one of them dies with its task
                os.kill(victim, signal.SIGKILL)
                killed.append(row)

        two = bake_table(tmp_path / "two.npz", SMALL, progress=False,
                         scheduler=c.scheduler_address, on_row=kill_once)
        assert killed
        with distributed.Client(c) as client:
            assert victim not in client.run(os.getpid).values()  # the nanny started a new one
    assert two.read_bytes() == one_table


def test_reference_render_by_bands_on_two_workers_is_byte_identical(tmp_path, cluster):
    from prefilter.render.driver import render
    from prefilter.render.tiles import render_tiled
    from prefilter.texture.io import write_image

    one = render(SCENE, "reference", spp=16, seed=5)
    write_image(tmp_path / "one.npy", one)
    two = render_tiled(SCENE, "reference", out=tmp_path / "two.npy", spp=16, seed=5,
                       tile_rows=3, scheduler=cluster.scheduler_address)
    assert one.tobytes() == two.tobytes()
    assert (tmp_path / "one.npy").read_bytes() == (tmp_path / "two.npy").read_bytes()
    assert not (tmp_path / "two.npy.parts").exists()


def test_colormap_rows_on_two_workers_are_byte_identical(tmp_path, cluster):
    from prefilter.colormap.commands import bake_table as bake_colormap_table

    c = np.linspace(0.0, 1.0, 3 * 64).reshape(64, 3) ** 2
    kw = dict(size=64, edge="clamp", chunk=8)
    one, ck1 = bake_colormap_table(c, (0, 1), 0.2, out=tmp_path / "one.npy", **kw)
    two, ck2 = bake_colormap_table(c, (0, 1), 0.2, out=tmp_path / "two.npy",
                                   scheduler=cluster.scheduler_address, **kw)
    assert one.table.tobytes() == two.table.tobytes()


def _numba_cache_of_worker():
    from prefilter.jit import cache_dir
    from prefilter.render.reference import reference_samples_kernel

    return (str(cache_dir()), str(reference_samples_kernel._cache._cache_path),
            len(reference_samples_kernel.signatures))


def test_workers_import_the_cached_numba_kernels(tmp_path, cluster):
    from prefilter.render.tiles import render_tiled

    render_tiled(SCENE, "reference", out=tmp_path / "a.npy", spp=4, seed=1, tile_rows=10,
                 scheduler=cluster.scheduler_address)
    with distributed.Client(cluster.scheduler_address) as client:
        info = client.run(_numba_cache_of_worker)
    for where, kernel_cache, _ in info.values():
        # the package's cache folder (jit.cache_dir), shared by every process of this machine
        assert Path(kernel_cache).is_relative_to(where)
    assert any(compiled for *_, compiled in info.values())  # the workers ran the kernel
    assert list(Path(kernel_cache).glob("*reference_samples_kernel*.nbi"))


def test_scheduler_that_does_not_answer_fails_within_the_timeout():
    address = _dead_address()
    t0 = time.perf_counter()
    with pytest.raises(PrefilterError, match=r"scheduler: expected a dask scheduler"):
        with Engine(address, timeout=2.0):
            pass
    assert time.perf_counter() - t0 < 10.0


def test_cli_scheduler_that_does_not_answer_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    from prefilter import distributed as d
    from prefilter.cli import main

    monkeypatch.setattr(d, "CONNECT_TIMEOUT", 2.0)
    with pytest.raises(SystemExit) as exc:
        main(["bake", "ltc-iso", "--res", "2", "--quiet", "-o", str(tmp_path / "t.npz"),
              "--scheduler", _dead_address()])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "scheduler: expected a dask scheduler" in err[0]


def test_environment_names_the_scheduler(monkeypatch):
    monkeypatch.setenv("DASK_SCHEDULER_ADDRESS", "tcp://10.0.0.1:8786")
    assert resolve_scheduler(None) == "tcp://10.0.0.1:8786"
    assert resolve_scheduler("local") == "local"
    monkeypatch.delenv("DASK_SCHEDULER_ADDRESS")
    assert resolve_scheduler(None) == SYNCHRONOUS
    assert resolve_scheduler(None, workers=2) == "local"
    with pytest.raises(PrefilterError, match="workers: applies to the local cluster only"):
        Engine("tcp://10.0.0.1:8786", workers=2)


def test_task_map_keeps_order_and_refuses_closures():
    assert task_map(math.pow, [(2, i) for i in range(4)]) == [1.0, 2.0, 4.0, 8.0]
    with pytest.raises(PrefilterError, match="func: expected a top-level function"):
        task_map(lambda x: x, [(1,)])


def test_glints_bake_cli_on_two_workers_is_byte_identical(tmp_path, cluster):
    """``prefilter bake glints --scheduler ADDRESS``: the level-0 chunks and CP cells as tasks
    on the cluster give the bytes of the bake in this process."""
    from click.testing import CliRunner

    from prefilter.cli import cli

    args = ["bake", "glints", "procedural:flakes:32:3", "--rank", "4", "--ndf-res", "16",
            "--block", "8", "--cell", "8", "--iters", "10", "--quiet"]
    runner = CliRunner()
    one = runner.invoke(cli, args + ["-o", str(tmp_path / "one.npz")])
    assert one.exit_code == 0, one.output
    two = runner.invoke(cli, args + ["-o", str(tmp_path / "two.npz"),
                                      "--scheduler", cluster.scheduler_address])
    assert two.exit_code == 0, two.output
    assert (tmp_path / "one.npz").read_bytes() == (tmp_path / "two.npz").read_bytes(), \
        _npz_differences(tmp_path / "one.npz", tmp_path / "two.npz")


def _npz_differences(a: Path, b: Path) -> str:
    """Which members of two ``.npz`` files differ (and, for the JSON header, which keys), so a
    failure says where the bytes part."""
    import json

    da, db = np.load(a), np.load(b)
    out = []
    for k in sorted(set(da.files) | set(db.files)):
        if k not in da.files or k not in db.files:
            out.append(f"{k}: only in one file")
        elif k == "header":
            ha, hb = (json.loads(str(d[k])) for d in (da, db))
            for s in sorted(set(ha) | set(hb)):
                va, vb = ha.get(s), hb.get(s)
                if isinstance(va, dict) and isinstance(vb, dict):
                    out += [f"header.{s}.{x}: {va.get(x)} != {vb.get(x)}"
                            for x in sorted(set(va) | set(vb)) if va.get(x) != vb.get(x)]
                elif va != vb:
                    out.append(f"header.{s}: {va} != {vb}")
        elif da[k].shape != db[k].shape or not np.array_equal(da[k], db[k]):
            n = int(np.sum(da[k] != db[k])) if da[k].shape == db[k].shape else -1
            out.append(f"{k}: {n} elements differ of {da[k].size}")
    return "; ".join(out) or "arrays equal, bytes differ"


def test_leadr_bands_on_two_workers_are_byte_identical(tmp_path, cluster):
    """``prefilter bake leadr --scheduler ADDRESS``: bands of rows and their mips as tasks on the
    cluster give the bytes of the bake in this process (every level file and the index)."""
    from click.testing import CliRunner

    from prefilter.cli import cli

    rng = np.random.default_rng(5)
    np.save(tmp_path / "h.npy", rng.normal(size=(64, 32)))
    runner = CliRunner()
    base = ["bake", "leadr", str(tmp_path / "h.npy"), "--base-roughness", "0.1"]
    one = runner.invoke(cli, base + ["-o", str(tmp_path / "one")])
    assert one.exit_code == 0, one.output
    two = runner.invoke(cli, base + ["-o", str(tmp_path / "two"), "--band-rows", "8",
                                     "--scheduler", cluster.scheduler_address])
    assert two.exit_code == 0, two.output
    dirs = [(tmp_path / d / "leadr.json").resolve().parent for d in ("one", "two")]
    files = sorted(p.name for p in dirs[0].iterdir())
    assert len(files) == 8 and files == sorted(p.name for p in dirs[1].iterdir())
    for name in files:
        assert (dirs[0] / name).read_bytes() == (dirs[1] / name).read_bytes(), name
