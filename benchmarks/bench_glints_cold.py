"""Cold- and warm-cache ``glints`` render of the docs' example scene (docs/glints.md, "Bake cost").

    python benchmarks/bench_glints_cold.py                 # docs/scenes.md's "A full example"
    python benchmarks/bench_glints_cold.py --scene S.json  # another scene

Runs ``prefilter render SCENE --method glints`` twice in subprocesses, with an empty glints cache
(``$PREFILTER_GLINTS_CACHE``) and an empty ``$TMPDIR`` in a fresh folder: the first render bakes
every normal map of the scene, the second loads the bakes. Records per run the wall time, the
CPU time (user + system) and the peak resident memory of the process (``os.wait4``), and for
the cold run the peak temporary disk: the bytes allocated under ``$TMPDIR`` plus the bake's parts
(``*.parts/``) and unfinished outputs (``.*`` files) in the cache, polled every 0.2 s; then the
size of the cache the bake leaves. The compiled kernels come from the Numba cache as they are
(the line says whether it held kernels of this source version; compilation is in the times
otherwise). The machine is shared: wall times vary with the load (printed), CPU times less.
Unless ``--no-warmup``, a 32 x 18 render of the docs' example with 32^2 maps (own throwaway
caches) runs first, so that the kernels of this source version are compiled and cached.
With ``--flip`` a ``glints-direct`` frame of the scene follows (not timed against the targets)
and the warm frame's HDR-FLIP against it is printed: the speed is not bought with the image.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def docs_example() -> dict:
    """The JSON scene of docs/scenes.md's "A full example" section."""
    text = (HERE.parent / "docs" / "scenes.md").read_text()
    section = text[text.index("## A full example"):]
    return json.loads(re.search(r"```json\n(.*?)```", section, re.S).group(1))


def docs_example_maps() -> dict:
    """The normal maps ``(H, W, 3)`` of :func:`docs_example`'s objects, by procedural kind
    (in the scene's order: gaussian, flakes)."""
    from prefilter.glints.pndf import as_normal_map
    from prefilter.render.scene import load_scene

    maps = [o.material.normal_map for o in load_scene(docs_example()).objects
            if getattr(o.material, "normal_map", None) is not None]
    return {m.spec.get("procedural"): as_normal_map(m.load()) for m in maps}


#: The warm-up renders twice in one process: as is, then with every serial-below threshold at 0
#: so that the parallel twins of the kernels compile too (a 32 x 18 frame runs the serial ones
#: only; the full frame of 256^2 maps then compiled the parallel query kernels, ~18 s of its
#: render).
WARMUP = """
import sys
from prefilter.cli import main
import prefilter.jit, prefilter.glints.query, prefilter.glints.brdf, prefilter.render.kernels
def render():
    try:
        main(sys.argv[1:])
    except SystemExit as e:
        if e.code:
            raise
render()
prefilter.jit.SERIAL_BELOW = prefilter.glints.query.SERIAL_BELOW = 0
prefilter.glints.brdf.RENDER_SERIAL_BELOW = prefilter.render.kernels.SERIAL_BELOW = 0
render()
"""


def warmup(root: Path, env: dict) -> float:
    """Compile the kernels a ``glints`` render and its bake call (Numba caches them by source
    version): render a 32 x 18 copy of the docs' example with 32^2 maps into a throwaway glints
    cache, serial and parallel kernels (:data:`WARMUP`). Returns its wall time."""
    small = docs_example()
    small["camera"].update(width=32, height=18)
    for obj in small["objects"]:
        obj["material"]["normal_map"]["size"] = 32
    (root / "warmup.json").write_text(json.dumps(small))
    (root / "warmup-cache").mkdir()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", WARMUP, "render", str(root / "warmup.json"),
                    "--method", "glints", "--out", str(root / "warmup.exr")], check=True,
                   capture_output=True,
                   env=dict(env, PREFILTER_GLINTS_CACHE=str(root / "warmup-cache")))
    return time.perf_counter() - t0


def disk_bytes(path: Path, temp_only: bool = False) -> int:
    """Bytes allocated under ``path`` (sparse files count what they hold); ``temp_only``: only
    bake parts (``*.parts/``) and unfinished files (names starting with a dot)."""
    total = 0
    for root, _, files in os.walk(path):
        in_parts = ".parts" in root
        for name in files:
            if temp_only and not (in_parts or name.startswith(".")):
                continue
            try:
                total += os.stat(os.path.join(root, name)).st_blocks * 512
            except OSError:  # removed while walking
                pass
    return total


def run(cmd: list[str], env: dict, log: Path, watch: list[tuple[Path, bool]] = ()) -> dict:
    """Run ``cmd`` (output to ``log``); wall and CPU seconds, peak RSS (MiB) of the process and
    the peak of the watched bytes."""
    peak = [0]
    done = threading.Event()

    def poll():
        while not done.is_set():
            peak[0] = max(peak[0], sum(disk_bytes(p, t) for p, t in watch))
            done.wait(0.2)

    watcher = threading.Thread(target=poll, daemon=True)
    t0 = time.perf_counter()
    with open(log, "wb") as fh:
        proc = subprocess.Popen(cmd, env=env, stdout=fh, stderr=subprocess.STDOUT)
        watcher.start()
        # wait4: the resource usage of this child alone (not of every child reaped so far)
        _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    done.set()
    watcher.join()
    if proc.returncode:
        sys.exit(f"failed ({proc.returncode}): {' '.join(cmd)}\n{log.read_text()}")
    return dict(wall=wall, cpu=usage.ru_utime + usage.ru_stime, rss=usage.ru_maxrss / 1024,
                temp=peak[0])


def stages(log: str) -> list[str]:
    """The bake's messages and the last state of each of its progress bars in a render's
    stderr (tqdm redraws a bar after carriage returns)."""
    last: dict[str, str] = {}
    for seg in re.split(r"[\r\n]+", log):
        seg = seg.strip()
        if seg.startswith("glints bake:") or re.match(r"^[\w ,.]+: +\d+%", seg):
            last[seg.split(":")[0] if "%" in seg else seg] = seg
    return list(last.values())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", type=Path, help="scene JSON [default: the docs' example]")
    ap.add_argument("--keep", action="store_true", help="keep the folder of caches and images")
    ap.add_argument("--no-warmup", action="store_true",
                    help="no small render first (compilation then counts in the cold run)")
    ap.add_argument("--flip", action="store_true",
                    help="then also render glints-direct and print the warm frame's HDR-FLIP "
                         "against it (after the timed runs)")
    a = ap.parse_args()

    from prefilter import jit

    kernels = jit.cache_dir()
    warm_kernels = kernels is not None and any(kernels.rglob("*.nbi"))
    root = Path(tempfile.mkdtemp(prefix="bench-glints-cold-"))
    scene = a.scene or root / "scene.json"
    if a.scene is None:
        scene.write_text(json.dumps(docs_example()))
    cache, tmp = root / "cache", root / "tmp"
    cache.mkdir()
    tmp.mkdir()
    env = dict(os.environ, PREFILTER_GLINTS_CACHE=str(cache), TMPDIR=str(tmp))
    render_cmd = [sys.executable, "-c", "from prefilter.cli import main; main()", "render",
                  str(scene), "--method"]
    cmd = render_cmd + ["glints", "--out"]
    print(f"scene {a.scene or 'docs/scenes.md example'}; Numba cache "
          f"{'held' if warm_kernels else 'did not hold'} kernels of this source version; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    if not a.no_warmup:
        print(f"warm-up render (compiles what the cache lacks): {warmup(root, env):.0f} s")
    cold = run(cmd + [str(root / "cold.exr")], env, root / "cold.log",
               [(tmp, False), (cache, True)])
    stored = disk_bytes(cache)
    warm = run(cmd + [str(root / "warm.exr")], env, root / "warm.log")
    mib = 2**20
    print(f"cold cache: {cold['wall']:.0f} s wall, {cold['cpu']:.0f} s CPU, peak RSS "
          f"{cold['rss']:.0f} MiB, peak temporary disk {cold['temp'] / mib:.0f} MiB; "
          f"cache left {stored / mib:.0f} MiB")
    print(f"warm cache: {warm['wall']:.1f} s wall, {warm['cpu']:.1f} s CPU, peak RSS "
          f"{warm['rss']:.0f} MiB")
    print(f"load average after: {os.getloadavg()[0]:.1f}")
    if a.flip:
        direct = run(render_cmd + ["glints-direct", "--out", str(root / "direct.exr")], env,
                     root / "direct.log")
        from prefilter.render.metrics import flip
        from prefilter.texture.io import read_image

        err = flip(read_image(root / "direct.exr"), read_image(root / "warm.exr")).mean
        print(f"glints vs glints-direct ({direct['wall']:.0f} s): HDR-FLIP {err:.4f}")
    print("the cold render's bake stages (the last state of each progress bar):")
    for line in stages((root / "cold.log").read_text(errors="replace")):
        print("  " + line)
    if a.keep:
        print(f"kept {root}")
    else:
        import shutil

        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
