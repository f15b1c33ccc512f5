"""Two bakes of one output, and a bake killed between a table and its sidecar.

Each bake runs as a subprocess (``python -m prefilter.cli bake ...``). The first one is held
right after its first checkpoint (a patched ``Checkpoints.save`` waits for a release file), so the
second one starts while the first surely runs: without a lock the second would discard or mix the
first one's rows. With ``--wait`` the second queues behind the first and its own table wins.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TIMEOUT = 300

#: Runs the CLI with ``Checkpoints.save`` paused after chunk 0 until ``$RELEASE`` exists.
_HELD_BAKE = """
import os, sys, time
from pathlib import Path
from prefilter.fileio import Checkpoints
save = Checkpoints.save
def held(self, chunk, **arrays):
    save(self, chunk, **arrays)
    if chunk == 0:
        print("checkpointed", flush=True)
        deadline = time.monotonic() + 120
        while not Path(os.environ["RELEASE"]).exists() and time.monotonic() < deadline:
            time.sleep(0.05)
Checkpoints.save = held
from prefilter.cli import main
main(sys.argv[1:])
"""

#: Runs the CLI with the sidecar write replaced by an immediate exit (a kill at that point).
_KILLED_BEFORE_SIDECAR = """
import os, sys
import prefilter.fileio
def killed(path, obj):
    os._exit(9)
prefilter.fileio.save_json_atomic = killed
from prefilter.cli import main
main(sys.argv[1:])
"""


def _cli(args, cwd, env=None, script=None) -> subprocess.Popen:
    cmd = ([sys.executable, "-c", script] if script else
           [sys.executable, "-m", "prefilter.cli"]) + ["bake", *args]
    return subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _start_held(args, tmp_path):
    import os

    release = tmp_path / "release"
    first = _cli(args, tmp_path, dict(os.environ, RELEASE=str(release)), _HELD_BAKE)
    line = first.stdout.readline().strip()
    assert line == "checkpointed", first.communicate(timeout=TIMEOUT)[1][-2000:]
    return first, release


def _finish(proc) -> tuple[int, str, str]:
    out, err = proc.communicate(timeout=TIMEOUT)
    return proc.returncode, out, err


def _ramp(d: Path) -> Path:
    from prefilter.texture.io import write_image

    x = np.linspace(0, 1, 64)
    return write_image(d / "ramp.png", np.stack([x, x**2, 1 - x], -1)[None], bits=16)


ISO = ["ltc-iso", "--res", "3", "--samples", "6", "--quiet", "-o", "X.npz"]


def _colormap(sigma_max: float) -> list[str]:
    return ["colormap", "ramp.png", "--sigma-max", str(sigma_max), "--size", "64",
            "-o", "t.png"]


@pytest.mark.parametrize("kind", ["ltc-iso", "colormap"])
def test_second_bake_fails_at_once_naming_the_first(kind, tmp_path):
    if kind == "ltc-iso":
        first_args, second_args = ISO, [*ISO[:4], "4", *ISO[5:]]
    else:
        _ramp(tmp_path)
        first_args, second_args = _colormap(0.2), _colormap(0.4)
    first, release = _start_held(first_args, tmp_path)
    try:
        rc, _, err = _finish(_cli(second_args, tmp_path))
    finally:
        release.touch()
        rc1, _, err1 = _finish(first)
    assert rc == 2, err[-2000:]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert f"pid {first.pid}" in lines[0] and "--wait" in lines[0]
    assert rc1 == 0, err1[-2000:]
    # the first bake's output, whole
    if kind == "ltc-iso":
        from prefilter.ltc.table import GGXTable

        assert GGXTable.load(tmp_path / "X.npz").settings["n_fit"] == 6
    else:
        from prefilter.colormap.table import ColormapTable

        assert ColormapTable.load(tmp_path / "t.png").sigma_max == 0.2
    assert not (tmp_path / "X.npz.lock").exists() and not (tmp_path / "t.png.lock").exists()


@pytest.mark.parametrize("kind", ["ltc-iso", "colormap"])
def test_second_bake_with_wait_queues_behind_the_first(kind, tmp_path):
    if kind == "ltc-iso":
        first_args, second_args = ISO, [*ISO[:4], "4", *ISO[5:], "--wait"]
    else:
        _ramp(tmp_path)
        first_args, second_args = _colormap(0.2), [*_colormap(0.4), "--wait"]
    first, release = _start_held(first_args, tmp_path)
    second = _cli(second_args, tmp_path)
    try:
        with pytest.raises(subprocess.TimeoutExpired):
            second.wait(timeout=8.0)  # blocked while the first holds the output
    finally:
        release.touch()
    rc1, _, err1 = _finish(first)
    rc2, _, err2 = _finish(second)
    assert rc1 == 0, err1[-2000:]
    assert rc2 == 0, err2[-2000:]
    if kind == "ltc-iso":
        from prefilter.ltc.fit_iso import FitSettings, bake_table
        from prefilter.ltc.table import GGXTable

        table = GGXTable.load(tmp_path / "X.npz")
        assert table.settings["n_fit"] == 4
        # no row of the first bake in it: the same bytes as the second bake on its own
        alone = bake_table(tmp_path / "alone.npz", FitSettings(res_theta=3, res_alpha=3, n_fit=4),
                           progress=False)
        assert (tmp_path / "X.npz").read_bytes() == alone.read_bytes()
    else:
        from prefilter.colormap.table import ColormapTable

        assert ColormapTable.load(tmp_path / "t.png").sigma_max == 0.4


def test_kill_between_colormap_table_and_sidecar_keeps_the_old_pair(tmp_path):
    from prefilter.colormap.table import ColormapTable

    _ramp(tmp_path)
    rc, _, err = _finish(_cli(_colormap(0.2), tmp_path))
    assert rc == 0, err[-2000:]
    old = ColormapTable.load(tmp_path / "t.png")
    rc, _, err = _finish(_cli(_colormap(0.4), tmp_path, script=_KILLED_BEFORE_SIDECAR))
    assert rc == 9, err[-2000:]  # died after writing the new table, before its sidecar
    table = ColormapTable.load(tmp_path / "t.png")
    assert table.sigma_max == 0.2
    np.testing.assert_array_equal(table.table, old.table)
    # the next bake finishes normally and replaces both
    rc, _, err = _finish(_cli(_colormap(0.4), tmp_path))
    assert rc == 0, err[-2000:]
    assert ColormapTable.load(tmp_path / "t.png").sigma_max == 0.4
