"""three.js as a client of the exported LTC tables: one GGX plane under one ``RectAreaLight``
rendered by three.js (WebGL2 in headless Chromium, SwiftShader) with three's stock tables
(``RectAreaLightUniformsLib``) and with ``prefilter export-ltc --preset threejs``, both compared
with the project's Monte Carlo reference (``prefilter.render.render(scene, "reference")``) of
the same scene.

Run (from the repository, after ``npm ci --prefix clients/threejs``)::

    PYTHONPATH=src python tools/threejs_compare.py [--width 160 --height 120 --spp 4096]

It prints one row per (roughness, tables): the relative RMSE over the plane's pixels,
``sqrt(mean((x - ref)^2)) / sqrt(mean(ref^2))`` over all pixels and the three channels (each
channel is one ``F0``: the material's linear colour ``F0 = (1, 0.5, 0.04)``, metalness 1).

The scene, in three.js's conventions (``clients/threejs/client.js``):

* ``MeshStandardMaterial``: ``roughness`` is perceptual (GGX ``alpha = roughness^2``),
  ``metalness = 1`` (no diffuse; ``specularColorBlended = color`` is ``F0``, ``specularF90 = 1``),
  so the LTC Fresnel ``F0 ltc_2.x + (1 - F0) ltc_2.y`` approximates the reference's Schlick
  Fresnel of ``F0``.
* ``RectAreaLight(0xffffff, L, w, h)``: radiance ``L`` (the light's uniform colour is
  ``color * intensity``), one-sided, emitting along its local ``-z``, which ``lookAt(target)``
  points at the target (lights turn as cameras do); its corners ``p +- w/2 x +- h/2 y``.
* Float render target (``FloatType``), no tone mapping, no output colour conversion: linear
  radiance read back by ``readRenderTargetPixels`` (row 0 at the bottom).
* The reference averages each pixel's area (sub-pixel positions), three.js shades the pixel
  centre: the client renders ``supersample^2`` times the pixels and box-filters them down.
"""

from __future__ import annotations

import argparse
import base64
import contextlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
CLIENT = REPO / "clients" / "threejs"
THREE = CLIENT / "node_modules" / "three" / "build" / "three.module.js"

ROUGHNESSES = (0.25, 0.5, 0.8)
F0 = (1.0, 0.5, 0.04)
CAMERA = {"origin": [0.0, 2.0, 2.2], "target": [0.0, 0.0, -0.2], "up": [0.0, 1.0, 0.0],
          "fov": 45.0}
PLANE_SIZE = (8.0, 8.0)
TABLES = ("stock", "prefilter")
HORIZONS = ("sphere", "clip")
LIGHT = {"center": [0.0, 0.9, -1.2], "target": [0.0, 0.0, 0.4], "width": 1.2, "height": 0.6,
         "radiance": 4.0}


def light_vertices(center, target, width, height, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Corners ``(4, 3)`` of a three.js ``RectAreaLight`` at ``center`` after ``lookAt(target)``.

    ``Matrix4.lookAt(eye, target, up)`` (lights turn as cameras): ``z = normalize(eye - target)``,
    ``x = normalize(up x z)``, ``y = z x x``; the shader's corners, in its order, are
    ``p + hw - hh``, ``p - hw - hh``, ``p - hw + hh``, ``p + hw + hh`` with ``hw = w/2 x``,
    ``hh = h/2 y``: counter-clockwise seen from ``-z``, the emitting side, as the project's quad
    lights are (emission along ``(v1 - v0) x (v2 - v0)``).
    """
    p, t, u = (np.asarray(v, np.float64) for v in (center, target, up))
    z = (p - t) / np.linalg.norm(p - t)
    x = np.cross(u, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    hw, hh = 0.5 * width * x, 0.5 * height * y
    return np.stack([p + hw - hh, p - hw - hh, p - hw + hh, p + hw + hh])


def client_options(roughness: float, width: int, height: int, f0=F0) -> dict:
    """The options of ``window.threejsClient.render`` (without ``tables``)."""
    return {"width": width, "height": height, "camera": CAMERA, "plane": {"size": PLANE_SIZE},
            "light": LIGHT, "roughness": roughness, "f0": list(f0)}


def reference_scene(roughness: float, width: int, height: int, f0=F0) -> dict:
    """The same scene in the project's format (``docs/scenes.md``): GGX ``alpha = roughness^2``,
    Schlick ``f0``, no diffuse, the light's corners from :func:`light_vertices`."""
    verts = light_vertices(LIGHT["center"], LIGHT["target"], LIGHT["width"], LIGHT["height"])
    return {
        "camera": {**CAMERA, "width": width, "height": height},
        "objects": [{"type": "plane", "center": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0],
                     "tangent": [1.0, 0.0, 0.0], "size": list(PLANE_SIZE),
                     "material": {"alpha": roughness ** 2, "f0": list(f0),
                                  "base_color": 0.0}}],
        "lights": [{"type": "quad", "vertices": verts.tolist(), "radiance": LIGHT["radiance"]}],
    }


@contextlib.contextmanager
def served_client(tables_dir):
    """Serve the client page, its ``node_modules`` and the exported ``tables_dir`` (symlinks in a
    temporary folder) at ``http://127.0.0.1:PORT/``; yields the URL of ``index.html``."""
    from prefilter.viewer import serve

    with tempfile.TemporaryDirectory(prefix="prefilter-threejs-") as d:
        for name in ("index.html", "client.js", "node_modules"):
            os.symlink(CLIENT / name, Path(d) / name)
        os.symlink(Path(tables_dir).resolve(), Path(d) / "tables")
        server, url = serve(d)
        try:
            yield url + "index.html"
        finally:
            server.shutdown()
            server.server_close()


def open_client(driver, url: str, timeout: float = 60.0) -> None:
    """Load the client page and wait for its module to run."""
    driver.set_script_timeout(timeout)
    driver.get(url)
    driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "const poll = () => window.threejsClient ? done('ok') : setTimeout(poll, 20);"
        "poll();")


def render_three(driver, opts: dict, tables: str, supersample: int = 1,
                 horizon: str = "sphere") -> np.ndarray:
    """Linear radiance ``(H, W, 3)`` (row 0 at the top) of the open client page: rendered at
    ``supersample`` times the size and box-filtered (each pixel the mean of its sub-pixels).

    ``tables``: ``"stock"`` or ``"prefilter"``; ``horizon``: ``"sphere"`` (three's shader) or
    ``"clip"`` (the polygon clipped at the horizon, see ``clients/threejs/client.js``)."""
    s = int(supersample)
    big = dict(opts, width=opts["width"] * s, height=opts["height"] * s, tables=tables,
               horizon=horizon)
    out = driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "window.threejsClient.render(arguments[0]).then(done,"
        " e => done({error: String(e && e.stack || e)}));", big)
    if "error" in out:
        raise RuntimeError(f"three.js client: {out['error']}")
    a = np.frombuffer(base64.b64decode(out["pixels"]), "<f4").reshape(
        big["height"], big["width"], 4)[::-1, :, :3].astype(np.float64)
    h, w = opts["height"], opts["width"]
    return a.reshape(h, s, w, s, 3).mean(axis=(1, 3))


def rel_rmse(img, ref) -> float:
    """``sqrt(mean((img - ref)^2)) / sqrt(mean(ref^2))`` over all pixels and channels."""
    return float(np.sqrt(np.mean((img - ref) ** 2)) / np.sqrt(np.mean(ref ** 2)))


def compare(driver, tables_dir, *args, **kwargs) -> list:
    """:func:`compare_open` on the client page served with the exported tables in
    ``tables_dir``."""
    with served_client(tables_dir) as url:
        open_client(driver, url)
        return compare_open(driver, *args, **kwargs)


def compare_open(driver, roughnesses=ROUGHNESSES, width: int = 160, height: int = 120,
                 spp: int = 4096, supersample: int = 4, seed: int = 0,
                 extras: bool = True) -> list:
    """One row (a dict) per roughness: relative RMSE against the ``reference`` render (``spp``
    samples) of three.js on the open client page (:func:`open_client`) with its stock tables
    (``stock``) and with the exported ones (``prefilter``), with three's shader (``*_sphere``)
    and with the polygon
    clipped at the horizon (``*_clip``); with ``extras``, also the project's own ``ltc`` method
    (``ltc``: same table, exact clipping, Python) and ``noise``: the reference against a second
    one of another seed (sqrt(2) times its Monte Carlo noise, a floor for the others).

    ``row[name]``: over all channels; ``row["channels"][name]``: per channel, i.e. per ``F0``
    of :data:`F0`; ``row["images"]``: the ``(H, W, 3)`` images."""
    from prefilter.render import render

    rows = []
    for r in roughnesses:
        sc = reference_scene(r, width, height)
        ref = render(sc, "reference", spp=spp, seed=seed).astype(np.float64)
        opts = client_options(r, width, height)
        imgs = {f"{k}_{h}": render_three(driver, opts, k, supersample, h)
                for h in HORIZONS for k in TABLES}
        if extras:
            imgs["ltc"] = render(sc, "ltc", spp=supersample * supersample).astype(np.float64)
            imgs["noise"] = render(sc, "reference", spp=spp, seed=seed + 1).astype(np.float64)
        rows.append({"roughness": r, "alpha": r * r,
                     **{k: rel_rmse(v, ref) for k, v in imgs.items()},
                     "channels": {k: tuple(rel_rmse(v[..., c], ref[..., c]) for c in range(3))
                                  for k, v in imgs.items()},
                     "images": {"reference": ref, **imgs}})
    return rows


LABELS = {"stock_sphere": "three.js, stock tables",
          "prefilter_sphere": "three.js, prefilter tables",
          "stock_clip": "three.js clipped, stock tables",
          "prefilter_clip": "three.js clipped, prefilter tables",
          "ltc": "prefilter `ltc` (Python)", "noise": "reference vs reference (seed 1)"}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--height", type=int, default=120)
    ap.add_argument("--spp", type=int, default=4096, help="reference samples per pixel")
    ap.add_argument("--supersample", type=int, default=4)
    ap.add_argument("--roughness", type=float, nargs="+", default=list(ROUGHNESSES))
    ap.add_argument("--save", type=Path, help="write the images of each row to this .npz")
    args = ap.parse_args(argv)
    if not THREE.is_file():
        print(f"{THREE} missing: run `npm ci --prefix clients/threejs`", file=sys.stderr)
        return 2
    from prefilter.ltc.export import export_preset
    from prefilter.viewer.browser import chromium

    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tables:
        export_preset("threejs", tables)  # = prefilter export-ltc --preset threejs -o DIR
        driver = chromium()
        try:
            rows = compare(driver, tables, args.roughness, args.width, args.height, args.spp,
                           args.supersample)
            revision = driver.execute_script("return window.threejsClient.revision;")
        finally:
            driver.quit()
    print(f"three.js r{revision}, {args.width} x {args.height} px ({args.supersample}^2 "
          f"sub-pixels), reference {args.spp} spp, {time.perf_counter() - t0:.0f} s")
    f0 = " | ".join(f"F0 = {f:g}" for f in F0)
    print(f"| roughness (alpha) | image | all channels | {f0} |")
    print("|---|---|---|" + "---|" * len(F0))
    for r in rows:
        for k, label in LABELS.items():
            ch = " | ".join(f"{100 * e:.2f} %" for e in r["channels"][k])
            print(f"| {r['roughness']:g} ({r['alpha']:.4g}) | {label} | {100 * r[k]:.2f} % | "
                  f"{ch} |")
    if args.save:
        np.savez_compressed(args.save, **{f"r{r['roughness']:g}_{k}": v for r in rows
                                          for k, v in r["images"].items()})
    return 0


if __name__ == "__main__":
    sys.exit(main())
