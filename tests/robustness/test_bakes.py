"""Kill-restart bakes (issue 10): SIGKILL a running ``prefilter bake`` at a random (seeded) point,
rerun the same command, and compare the output byte for byte with an uninterrupted bake.

Chunked bakes (ltc-iso rows, ltc-aniso entry chunks, glints level-0 rows / levels / cells,
colour-map sigma rows) are killed after their first checkpoint appears in ``<out>.parts/``, at a
random delay of about the time the remaining chunks take. The LEADR bake has no chunks (a
2048^2 map takes 1 s of moments and 2 s of EXR writing; every level file is atomic and the index
with their checksums is written last), so it is killed at a random time after start. A trial
whose bake finishes before the kill is repeated with half the delay. The fast suite runs one
trial of ltc-iso and glints; ``-m slow`` runs three trials of every bake.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest

TIMEOUT = 600


@dataclass(frozen=True)
class Bake:
    """``args(inputs, out)``: the words after ``prefilter bake``; ``out``: output name in the
    work directory; ``chunked``: checkpoints in ``<out>.parts/``; ``delay``: range (s) of the
    random kill delay after the first checkpoint (or after start when not chunked)."""

    args: Callable[[Path, Path], list[str]]
    out: str
    chunked: bool
    delay: tuple[float, float]


def _colormap_input(d: Path) -> Path:
    from prefilter.texture.io import write_image

    x = np.linspace(0, 1, 64)
    return write_image(d / "ramp.png", np.stack([x, x**2, 1 - x], -1)[None], bits=16)


def _height_input(d: Path) -> Path:
    from prefilter.texture.io import write_image

    rng = np.random.default_rng(11)
    return write_image(d / "height.exr", rng.normal(size=(256, 256)))


BAKES = {
    "ltc-iso": Bake(lambda i, o: ["ltc-iso", "--res", "4", "--samples", "8", "-o", str(o)],
                    "iso.npz", True, (0.0, 0.8)),
    "ltc-aniso": Bake(lambda i, o: ["ltc-aniso", "--res", "2", "--steps", "20", "--chunk", "3",
                                    "-o", str(o)], "aniso.npz", True, (0.0, 1.0)),
    "glints": Bake(lambda i, o: ["glints", "procedural:gaussian:64:1", "--ndf-res", "16",
                                 "--block", "8", "--rank", "4", "--cell", "16", "--iters", "20",
                                 "-o", str(o)], "glints.npz", True, (0.0, 0.8)),
    # the render bake's layout: 16-bit a, b, 8-bit c, upper levels exact, one image per group
    "glints-exact": Bake(lambda i, o: ["glints", "procedural:gaussian:64:1", "--ndf-res", "16",
                                       "--block", "8", "--rank", "4", "--cell", "16",
                                       "--iters", "20", "--code-bits", "16", "--c-bits", "8",
                                       "--exact-from-level", "1", "--exact-cell", "1",
                                       "-o", str(o)], "glints.npz", True, (0.0, 0.8)),
    "colormap": Bake(lambda i, o: ["colormap", str(_colormap_input(i)), "--sigma-max", "0.2",
                                   "--size", "1024", "-o", str(o)], "table.exr", True,
                     (0.0, 0.4)),
    "leadr": Bake(lambda i, o: ["leadr", str(_height_input(i)), "-o", str(o),
                                "--base-roughness", "0.05"], "leadr", False, (0.5, 3.0)),
}


def _cmd(bake: Bake, inputs: Path, work: Path) -> list[str]:
    """The command, run from ``inputs.parent`` with relative paths: bakes record their input
    path (colour-map sidecar), which must not differ between the trial and the reference."""
    root = str(inputs.parent) + os.sep
    args = [a.removeprefix(root) for a in bake.args(inputs, work / bake.out)]
    quiet = ["--quiet"] if args[0] in ("ltc-iso", "ltc-aniso", "glints") else []  # progress bars
    return [sys.executable, "-m", "prefilter.cli", "bake", *args, *quiet]


def _outputs(work: Path) -> dict[str, bytes]:
    """Every file under ``work`` (hidden temporary files of a killed atomic write, and the
    hidden version folders that a table's visible links point into, excluded)."""
    return {str(p.relative_to(work)): p.read_bytes() for p in sorted(work.rglob("*"))
            if p.is_file() and not any(n.startswith(".") for n in p.relative_to(work).parts)}


def _run(cmd, cwd) -> None:
    r = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT)
    assert r.returncode == 0, r.stderr[-2000:]


class References:
    """Uninterrupted bakes, started on first use (concurrently with the first trial: the
    machine's cores are otherwise idle while a trial sleeps) and shared by later trials."""

    def __init__(self, factory):
        self.factory, self.procs, self.done = factory, {}, {}

    def start(self, kind: str) -> None:
        if kind in self.procs:
            return
        root = self.factory.mktemp(f"ref-{kind}")
        inputs, work = root / "in", root / "work"
        inputs.mkdir()
        work.mkdir()
        proc = subprocess.Popen(_cmd(BAKES[kind], inputs, work), cwd=root,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        self.procs[kind] = (proc, work)

    def get(self, kind: str) -> dict[str, bytes]:
        self.start(kind)
        if kind not in self.done:
            proc, work = self.procs[kind]
            _, err = proc.communicate(timeout=TIMEOUT)
            assert proc.returncode == 0, err[-2000:]
            self.done[kind] = _outputs(work)
            assert self.done[kind], f"{kind}: the bake wrote nothing"
        return self.done[kind]


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    refs = References(tmp_path_factory)
    yield refs
    for proc, _ in refs.procs.values():
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _checkpoints(parts: Path) -> int:
    try:
        return sum(1 for p in parts.iterdir() if p.suffix == ".npz" and not p.name.startswith("."))
    except FileNotFoundError:
        return 0


def kill_restart(kind: str, seed: int, root: Path) -> dict:
    """One trial: start, SIGKILL at a seeded random point, rerun to completion.

    If the bake finishes before the kill (a loaded machine is unpredictable; also a chunked bake
    killed after it removed its parts, while exiting), the attempt is discarded and repeated
    with half the delay, up to 4 times. Returns the outputs and what happened: ``killed`` (the
    process died of SIGKILL mid-bake), ``parts`` (checkpoints it left), ``attempts``.
    """
    import shutil

    bake = BAKES[kind]
    rng = np.random.default_rng([zlib.crc32(kind.encode()), seed])
    inputs, work = root / "in", root / "work"
    inputs.mkdir()
    cmd = _cmd(bake, inputs, work)
    parts = work / (bake.out + ".parts")
    scale = 1.0
    for attempt in range(1, 5):
        shutil.rmtree(work, ignore_errors=True)
        work.mkdir()
        delay = scale * float(rng.uniform(*bake.delay))
        proc = subprocess.Popen(cmd, cwd=root, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        try:
            deadline = time.monotonic() + TIMEOUT
            if bake.chunked:
                while _checkpoints(parts) == 0 and proc.poll() is None:
                    assert time.monotonic() < deadline, "no checkpoint appeared"
                    time.sleep(0.01)
            time.sleep(delay)
            proc.send_signal(signal.SIGKILL)
        finally:
            proc.wait(timeout=TIMEOUT)
        n_parts = _checkpoints(parts)  # what the killed process left
        # a chunked bake killed after removing its parts had finished (it was exiting): that
        # kill interrupted nothing
        killed = proc.returncode == -signal.SIGKILL and (n_parts > 0 or not bake.chunked)
        if killed:
            break
        scale *= 0.5
    _run(cmd, root)
    return {"outputs": _outputs(work), "killed": killed, "parts": n_parts,
            "leftover_parts": parts.exists(), "attempts": attempt}


def _check(kind, seed, references, tmp_path):
    references.start(kind)
    res = kill_restart(kind, seed, tmp_path)
    ref = references.get(kind)
    assert res["killed"], f"{kind}: the bake finished before the kill (trial not interrupted)"
    if BAKES[kind].chunked:
        assert res["parts"] >= 1
        assert not res["leftover_parts"], "the parts directory survived a finished bake"
    assert res["outputs"].keys() == ref.keys()
    for name, data in ref.items():
        assert res["outputs"][name] == data, f"{kind}: {name} differs from the uninterrupted bake"


@pytest.mark.parametrize("kind", ["ltc-iso", "glints", "glints-exact"])
def test_kill_restart_fast(kind, references, tmp_path):
    _check(kind, 0, references, tmp_path)


def test_concurrent_bakes_of_one_output(references, tmp_path):
    """Two processes baking the same glints output at once with ``--wait`` (as pytest workers
    sharing the render cache do) both succeed, one after the other, and leave the uninterrupted
    bake's bytes, no parts directory and no lock file. Without ``--wait`` the second fails at
    once (tests/robustness/test_concurrent_bakes.py)."""
    references.start("glints")
    inputs, work = tmp_path / "in", tmp_path / "work"
    inputs.mkdir()
    work.mkdir()
    cmd = [*_cmd(BAKES["glints"], inputs, work), "--wait"]
    procs = [subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True) for _ in range(2)]
    for p in procs:
        _, err = p.communicate(timeout=TIMEOUT)
        assert p.returncode == 0, err[-2000:]
    assert _outputs(work) == references.get("glints")


def test_bake_if_missing_waits_for_a_running_bake(tmp_path):
    """``bake_if_missing`` called while another process holds the bake's lock returns only once
    that bake has finished, and then does not bake again."""
    from prefilter.glints.bake import bake_if_missing

    out = tmp_path / "g.npz"
    holder = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time; from pathlib import Path; from prefilter.fileio import exclusive_lock\n"
         "with exclusive_lock(sys.argv[1] + '.lock'):\n"
         "    print('locked', flush=True); time.sleep(1.0); Path(sys.argv[1]).write_bytes(b'x')",
         str(out)], stdout=subprocess.PIPE, text=True)
    assert holder.stdout.readline().strip() == "locked"
    nm = np.zeros((16, 16, 3))
    nm[..., 2] = 1.0
    baked = bake_if_missing(nm, out, ndf_res=16, block=8, rank=2, cell=16, progress=False)
    holder.wait(timeout=TIMEOUT)
    assert not baked and out.read_bytes() == b"x"
    assert not Path(str(out) + ".lock").exists()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3])
@pytest.mark.parametrize("kind", list(BAKES))
def test_kill_restart(kind, seed, references, tmp_path):
    _check(kind, seed, references, tmp_path)


@pytest.mark.slow  # tests/ltc/test_fit_iso.py covers the same in the fast suite
def test_checkpoint_per_chunk_and_resume(tmp_path):
    """In process: a bake interrupted after row 1 keeps rows 0-1 as parts, and the resumed bake
    fits only the remaining rows and writes the same bytes as an uninterrupted one."""
    from prefilter.ltc.fit_iso import FitSettings, bake_table

    s = FitSettings(res_theta=3, res_alpha=3, n_fit=6, quad_nodes=24)
    ref = bake_table(tmp_path / "ref.npz", s, progress=False)

    class Stop(Exception):
        pass

    def stop_after_1(i):
        if i == 1:
            raise Stop

    out = tmp_path / "t.npz"
    with pytest.raises(Stop):
        bake_table(out, s, progress=False, on_row=stop_after_1)
    parts = sorted(p.name for p in (tmp_path / "t.npz.parts").glob("0*.npz"))
    assert parts == ["000000.npz", "000001.npz"] and not out.exists()
    fitted = []
    bake_table(out, s, progress=False, on_row=fitted.append)
    assert fitted == [2]
    assert out.read_bytes() == ref.read_bytes()
    assert not (tmp_path / "t.npz.parts").exists()


def test_atomic_write_leaves_target_intact(tmp_path):
    """A writer that dies inside ``atomic_path`` leaves the previous file untouched and no
    temporary file once the bake's checkpoints are cleared."""
    from prefilter.fileio import Checkpoints, atomic_path, save_npz_atomic

    out = tmp_path / "t.npz"
    save_npz_atomic(out, a=np.arange(3))
    before = out.read_bytes()
    with pytest.raises(RuntimeError):
        with atomic_path(out) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError
    assert out.read_bytes() == before
    # a SIGKILL skips the cleanup above: simulate its leftover, which clear() removes
    (tmp_path / ".t.npz.abc123.npz").write_bytes(b"half")
    Checkpoints(out, {"k": 1}).clear()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.npz"]
    assert os.path.getsize(out) == len(before)


def test_damaged_checkpoint_is_recomputed(tmp_path):
    """A part damaged on disk fails its checksum and is fitted again, not trusted: the output
    equals that of an uninterrupted bake."""
    from prefilter.ltc.fit_iso import FitSettings, bake_table

    s = FitSettings(res_theta=2, res_alpha=2, n_fit=4, quad_nodes=16)
    ref = bake_table(tmp_path / "ref.npz", s, progress=False).read_bytes()

    class Stop(Exception):
        pass

    def stop(i):
        raise Stop

    out = tmp_path / "t.npz"
    with pytest.raises(Stop):
        bake_table(out, s, progress=False, on_row=stop)
    part = tmp_path / "t.npz.parts" / "000000.npz"
    data = bytearray(part.read_bytes())
    data[len(data) // 2] ^= 0x01
    part.write_bytes(bytes(data))
    fitted = []
    bake_table(out, s, progress=False, on_row=fitted.append)
    assert sorted(fitted) == [0, 1]
    assert out.read_bytes() == ref
