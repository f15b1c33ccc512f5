"""Record every registered method's images on a fixed set of small scenes, or compare with a record.

A guard for changes that must not change images (re-layering, moving kernels)::

    python tools/render_digests.py record DIR     # before: DIR/scenes/*.json, images.npz
    python tools/render_digests.py compare DIR    # after it: relative RMSE per method and scene

``record`` writes the scenes as JSON files, so ``compare`` only needs
:func:`prefilter.render.render` and the scene format. A method that cannot render a scene (wrong
light type, ...) is recorded with its error message; ``compare`` reports methods whose success
or failure changed. ``--rename OLD=NEW[?k=v&k=v]`` maps a method name of the record to a name
(and parameters) of today's registry.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

W, H = 48, 32


def _scenes() -> dict[str, dict]:
    from prefilter.report.demo import leadr_scene, showcase_scene
    from prefilter.ltc.aniso.demo import demo_scene
    from prefilter.glints.render import measurement_scene

    leadr_env = leadr_scene(W, H)
    leadr_env["lights"] = [measurement_scene(1.0, "flakes", 64, W, H, "environment")["lights"][0]]
    return {
        "showcase-near": showcase_scene(1.0, W, H),
        "showcase-far": showcase_scene(4.0, W, H),
        "aniso": demo_scene(W, H),
        "leadr-point": leadr_scene(W, H),
        "leadr-env": leadr_env,
        "glints-point": measurement_scene(2.0, "flakes", 64, W, H, "point"),
        "glints-quad": measurement_scene(2.0, "flakes", 64, W, H, "quad"),
    }


def _render(scene_path, method, params):
    from prefilter.render import render

    kwargs = {"params": params} if params else {}
    spp = 4 if method.endswith("reference") else 1
    return render(str(scene_path), method, spp=spp, seed=3, **kwargs)


def record(out: Path) -> None:
    from prefilter.render.methods import available

    (out / "scenes").mkdir(parents=True, exist_ok=True)
    images, errors = {}, {}
    for name, scene in _scenes().items():
        path = out / "scenes" / f"{name}.json"
        path.write_text(json.dumps(scene, indent=1))
        for method in available():
            # glint bakes cost minutes per normal map: glint methods only on the glint scenes
            if method.startswith("glints") != name.startswith("glints"):
                continue
            if method == "glints-wang" and name != "glints-point":
                continue
            key = f"{method}|{name}"
            try:
                images[key] = _render(path, method, None)
                print(f"{key}: ok", flush=True)
            except Exception as exc:  # noqa: BLE001  (recorded: a method may not take a scene)
                errors[key] = f"{type(exc).__name__}: {exc}"
                print(f"{key}: {errors[key][:100]}", flush=True)
    np.savez_compressed(out / "images.npz", **images)
    (out / "errors.json").write_text(json.dumps(errors, indent=1))


def compare(out: Path, renames: dict[str, tuple[str, dict]], methods=None) -> int:
    images = dict(np.load(out / "images.npz"))
    errors = json.loads((out / "errors.json").read_text())
    worst = 0.0
    bad = 0
    for key in sorted(set(images) | set(errors)):
        method, name = key.split("|")
        if methods and method not in methods:
            continue
        new, params = renames.get(method, (method, {}))
        path = out / "scenes" / f"{name}.json"
        try:
            img = _render(path, new, params)
        except Exception as exc:  # noqa: BLE001
            if key not in errors:
                print(f"{key}: now fails: {type(exc).__name__}: {exc}")
                bad += 1
            continue
        if key in errors:
            print(f"{key}: now renders (failed before: {errors[key][:80]})")
            continue
        ref = images[key]
        rel = float(np.sqrt(np.mean((img - ref) ** 2)) / max(np.sqrt(np.mean(ref**2)), 1e-30))
        worst = max(worst, rel)
        flag = "" if rel <= 1e-6 else "   <-- differs"
        bad += rel > 1e-6
        print(f"{key}: relative RMSE {rel:.2e}{flag}", flush=True)
    print(f"worst relative RMSE {worst:.2e}; {bad} differing or newly failing")
    return 1 if bad else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("mode", choices=("record", "compare"))
    ap.add_argument("dir", type=Path)
    ap.add_argument("--rename", action="append", default=[], metavar="OLD=NEW[?k=v&...]")
    ap.add_argument("--methods", default="",
                    help="comma-separated methods to compare (default all)")
    a = ap.parse_args(argv)
    if a.mode == "record":
        record(a.dir)
        return 0
    renames = {}
    for r in a.rename:
        old, new = r.split("=", 1)
        name, _, q = new.partition("?")
        renames[old] = (name, dict(kv.split("=", 1) for kv in q.split("&") if kv))
    return compare(a.dir, renames, [m for m in a.methods.split(",") if m])


if __name__ == "__main__":
    sys.exit(main())
