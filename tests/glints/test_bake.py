"""The bake's progress on stderr (command, render cache) and its memory and temporary disk."""

import copy
import threading

import numpy as np
import pytest
from maps import sinusoid

from prefilter.glints import bake as gbake
from prefilter.glints.bake import bake
from prefilter.glints.levels import LevelFile

SMALL = dict(rank=4, ndf_res=16, block=8, support=0.4, cell=8, n_iter_max=10)


def test_bake_reports_what_where_and_each_stage(tmp_path, capsys):
    out = tmp_path / "m.npz"
    bake(sinusoid(16, px=16, py=8), out, progress=True, **SMALL)
    err = capsys.readouterr().err
    assert "glints bake: normal map 16x16" in err and f"-> {out}" in err
    assert f"{out}.parts" in err  # where the resumable parts go
    for stage in ("level 0 NDF images", "coarser levels", "CP fit at rank 2",
                  "CP refit, encoding", "KiB -> "):
        assert stage in err, stage


def test_quiet_bake_is_silent(tmp_path, capsys):
    bake(sinusoid(16, px=16, py=8), tmp_path / "m.npz", progress=False, **SMALL)
    assert capsys.readouterr().err == ""


def test_file_summary_keeps_ten_significant_digits(tmp_path):
    """The header's summary is the returned summary with its floats at 10 significant digits
    (so last-bit differences of the error sums do not change the file's bytes)."""
    from prefilter.glints.store import load

    summary = bake(sinusoid(16, px=16, py=8), tmp_path / "m.npz", progress=False, **SMALL)
    stored = load(tmp_path / "m.npz").header["summary"]
    full = summary["rel_l2_error"]
    assert stored["rel_l2_error"] == float(f"{full:.10g}") and 0.0 < full
    assert stored["rel_l2_error_per_level"] == [float(f"{x:.10g}")
                                                for x in summary["rel_l2_error_per_level"]]
    assert stored["blocks_kept"] == summary["blocks_kept"]  # integers as they are
    assert gbake.significant({"a": [1.23456789012345, 7], "b": float("nan")})["a"] == \
        [1.234567890, 7]


def test_render_cache_bake_reports_its_file_then_loads_silently(tmp_path, monkeypatch, capsys):
    from prefilter.glints.render import baked_surface

    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(tmp_path / "cache"))
    nm = sinusoid(16, px=16, py=8)
    small = dict(rank=4, ndf_res=16, block=8, n_iter_max=10)
    baked_surface(nm, settings=small, progress=True)
    err = capsys.readouterr().err
    assert "glints bake: normal map 16x16" in err and str(tmp_path / "cache") in err
    baked_surface(nm.copy(), settings=small, progress=True)  # from the cache
    assert capsys.readouterr().err == ""


def test_render_passes_its_progress_to_the_bake(monkeypatch):
    """``glints`` renders hand the render's ``progress`` (``--quiet``) to ``baked_surface``."""
    from prefilter.glints import render as grender
    from prefilter.render.scene import load_scene

    seen = []

    class Stop(Exception):
        pass

    def spy(normal_map, *, direct=False, settings=None, progress=False):
        seen.append(progress)
        raise Stop

    monkeypatch.setattr(grender, "baked_surface", spy)
    monkeypatch.setattr(grender, "bake_maps", lambda scene, progress=False, settings=None: None)
    scene = load_scene(grender.measurement_scene(2.0, "flakes", 16, width=4, height=3))
    for progress in (True, False):
        try:
            grender.render_glints(scene, _settings(progress))
        except Stop:
            pass
    assert seen == [True, False]


def test_render_bakes_every_map_before_loading_one(monkeypatch):
    """A render bakes the scene's missing maps first, then loads them: the bakes' memory does not
    add to loaded maps'."""
    from prefilter.glints import render as grender
    from prefilter.render.scene import load_scene

    events = []

    class Stop(Exception):
        pass

    def bake_spy(normal_map, out, **kwargs):
        events.append("bake")
        return True

    def load_spy(*args, **kwargs):
        events.append("load")
        raise Stop

    monkeypatch.setattr(grender, "bake_if_missing", bake_spy)
    monkeypatch.setattr(grender, "load", load_spy)
    doc = grender.measurement_scene(2.0, "flakes", 16, width=4, height=3)
    doc["objects"].append(copy.deepcopy(doc["objects"][0]))
    scene = load_scene(doc)
    try:
        grender.render_glints(scene, _settings(False))
    except Stop:
        pass
    assert events.count("bake") >= 2 and events.index("load") >= 2  # both maps, then a load


def _settings(progress):
    from prefilter.render.methods import RenderSettings

    return RenderSettings(spp=1, seed=0, jitter=(0.0, 0.0), progress=progress)


def test_bake_maps_no_level_and_reads_at_most_a_cell_or_row(tmp_path, monkeypatch):
    """Levels are read by rows of centres or cells and never memory-mapped (a map's pages count
    in the process's memory), so the bake's memory does not grow with the map."""
    largest = [0]
    read = LevelFile.read

    def counted(self, *args, **kwargs):
        out = read(self, *args, **kwargs)
        largest[0] = max(largest[0], out.shape[0] * out.shape[1])
        return out

    def no_map(*args, **kwargs):
        raise AssertionError("a level was memory-mapped")

    monkeypatch.setattr(LevelFile, "read", counted)
    monkeypatch.setattr(np.lib.format, "open_memmap", no_map)
    monkeypatch.setattr(np, "memmap", no_map)
    nm = sinusoid(32, px=16, py=8)
    bake(nm, tmp_path / "m.npz", progress=False, **SMALL)
    # level 0 has 8 x 8 centres; a cell holds (cell / stride0)^2 = 4 of them, a row 8
    assert 0 < largest[0] <= 8


def test_temporary_disk_is_the_uncompressed_pyramid_at_most(tmp_path, monkeypatch):
    """Peak bytes of the parts folder (polled while the bake runs, and at its end) stay within
    the uncompressed pyramid plus the checkpoints; none are left behind."""
    out = tmp_path / "m.npz"
    parts = tmp_path / "m.npz.parts"
    peak, done = [0], threading.Event()

    def usage():
        return sum(f.stat().st_blocks * 512 for f in parts.glob("*") if f.is_file())

    def poll():
        while not done.is_set():
            try:
                peak[0] = max(peak[0], usage())
            except OSError:
                pass
            done.wait(0.01)

    save = gbake.save

    def at_end(*args, **kwargs):  # the parts are complete just before the output is written
        peak[0] = max(peak[0], usage())
        return save(*args, **kwargs)

    monkeypatch.setattr(gbake, "save", at_end)
    t = threading.Thread(target=poll)
    t.start()
    try:
        s = bake(sinusoid(32, px=16, py=8), out, progress=False, **SMALL)
    finally:
        done.set()
        t.join()
    assert 0 < peak[0] <= 1.1 * s["raw_bytes"] + 400_000
    assert not parts.exists()


def _pickled_map(fn, *iterables):
    """``map`` through pickle, as a cluster's workers run tasks: the task and its arguments
    must be picklable (top-level functions, no closures)."""
    import pickle

    return [pickle.loads(pickle.dumps(fn))(*pickle.loads(pickle.dumps(args)))
            for args in zip(*iterables)]


KW_EXACT = dict(SMALL, exact_from_level=1, exact_cell=1, code_bits=16, c_bits=8)


def test_tasks_through_any_map_give_the_same_bytes(tmp_path):
    """The bake's tasks (level-0 chunks, CP cells) run through ``map_fn`` as pickled top-level
    functions, in any order of execution, give the default bake's bytes."""
    nm = sinusoid(32, px=16, py=8)
    bake(nm, tmp_path / "a.npz", progress=False, **KW_EXACT)
    calls = []

    def reversed_map(fn, *iterables):  # runs the tasks last to first, returns them in order
        args = list(zip(*iterables))
        calls.append((fn.__name__, len(args)))
        out = _pickled_map(fn, *zip(*args[::-1])) if args else []
        return out[::-1]

    bake(nm, tmp_path / "b.npz", progress=False, map_fn=reversed_map, **KW_EXACT)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    assert [c[0] for c in calls] == ["level0_task", "fit_cell_task", "refit_cell_task"]
    assert all(n > 1 for _, n in calls)


@pytest.mark.slow
def test_tasks_on_a_process_pool_give_the_same_bytes(tmp_path):
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    nm = sinusoid(32, px=16, py=8)
    bake(nm, tmp_path / "a.npz", progress=False, **KW_EXACT)
    with ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("spawn")) as pool:
        bake(nm, tmp_path / "b.npz", progress=False, map_fn=pool.map, **KW_EXACT)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_coarser_levels_in_column_strips_are_the_same_images(tmp_path, monkeypatch):
    """A level built in column strips (the filter's window of rows over a byte cap) holds the
    images of the whole-row build bit for bit, and the bake the same codes."""
    from prefilter.glints.store import load

    nm = sinusoid(64, px=16, py=8)
    kw = dict(SMALL, keep_parts=True, progress=False)
    bake(nm, tmp_path / "rows.npz", **kw)
    monkeypatch.setattr(gbake, "LEVEL_RING_BYTES", 16 * 16 * 4 * 15 * 3)  # one-column strips
    bake(nm, tmp_path / "strips.npz", **kw)
    for lv in range(3):
        a = np.load(tmp_path / "rows.npz.parts" / f"level{lv}.npy")
        b = np.load(tmp_path / "strips.npz.parts" / f"level{lv}.npy")
        assert np.array_equal(a, b), lv
    ga, gb = load(tmp_path / "rows.npz"), load(tmp_path / "strips.npz")
    assert all(np.array_equal(ga.codes[k], gb.codes[k]) for k in ga.codes)
