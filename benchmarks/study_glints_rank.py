"""Brushed glint map: compression error vs rank budget, rank cap, code width and CP convergence.

    python benchmarks/study_glints_rank.py --out rank.jsonl          # the default settings
    python benchmarks/study_glints_rank.py --out rank.jsonl \
        --setting 'b48-16-tol0={"code_bits": 16, "tol": 0}'           # one more setting
    python benchmarks/study_glints_rank.py --table rank.jsonl        # only print the table

The brushed map's 8 cells of issue #9's matrix (:mod:`study_glints_scenes`): point light and
environment light with ``--same-estimator`` (``glints`` shades with the unprefiltered SG
estimator: the FLIP between the frames is the compression error alone), plane and sphere (sphere:
FLIP over the object's pixels), mid and far. ``glints-direct`` does not depend on the bake: its 8
frames are rendered once into ``--frames``. Per setting (a JSON object overriding
:data:`prefilter.glints.bake.BAKE_SETTINGS`, i.e. :func:`prefilter.glints.bake.bake` keys) one
row: wall time of the first ``glints`` frame (the bake when it was not cached), the bake
summary (stored MB, relative L2 error, largest group rank), per cell FLIP (HDR, and capped at +12
stops) and the "leak": pixels where ``glints > 0`` and ``glints-direct == 0`` and their largest
value relative to the ``glints-direct`` frame maximum.

``"exact_from_level": L`` (a bake key) stores every group of pyramid levels
``>= L`` as its exact non-negative CP (:func:`prefilter.glints.cp.exact_cp`; ranks up to 192 on
this map). ``L = 0`` is lossless up to the codes' rounding: its FLIP is what the query (pyramid
resampling, bilinear NDF lookup, blank blocks) costs without compression error. Bakes go to
``$PREFILTER_GLINTS_CACHE``; set it to a scratch directory.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))

CELLS = tuple((lt, sh, d) for lt in ("point", "environment") for sh in ("plane", "sphere")
              for d in ("mid", "far"))
#: Rec. 709 luminance weights (the leak is counted on luminance)
LUM = np.array([0.2126, 0.7152, 0.0722])
DEFAULT_SETTINGS = {
    "b48 8-bit (render)": {},
    "b48 16-bit": {"code_bits": 16},
    "b96 8-bit": {"rank": 96},
    "b96 16-bit": {"rank": 96, "code_bits": 16},
    "b48 16-bit tol 0": {"code_bits": 16, "tol": 0.0},
    "b96 16-bit tol 0": {"rank": 96, "code_bits": 16, "tol": 0.0},
    "b96 16-bit tol 0 max_rank 128": {"rank": 96, "code_bits": 16, "tol": 0.0, "max_rank": 128},
    "lossless 16-bit": {"code_bits": 16, "exact_from_level": 0},
    "b48 16-bit tol 0, levels >= 2 exact": {"code_bits": 16, "tol": 0.0, "exact_from_level": 2},
}


def _scene(cell):
    import study_glints_scenes as st

    from prefilter.render.scene import load_scene

    lights, shape, dist = cell
    return load_scene(st.scene(shape, st.DISTANCES[dist], "brushed", lights))


def _name(cell) -> str:
    return "_".join(cell)


def direct_frames(folder: Path) -> dict:
    """``glints-direct`` frame ``(H, W, 3)``, object mask and seconds per cell (rendered once,
    kept in ``folder``)."""
    import study_glints_scenes as st

    from prefilter.render.driver import render

    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for c in CELLS:
        f = folder / f"direct_{_name(c)}.npz"
        if not f.exists():
            sc = _scene(c)
            t0 = time.perf_counter()
            img = render(sc, "glints-direct")
            np.savez(f, img=img, hit=st.coverage(sc)[1], t=time.perf_counter() - t0)
        d = np.load(f)
        out[c] = (d["img"], d["hit"], float(d["t"]))
    return out


def leak(test: np.ndarray, reference: np.ndarray) -> tuple[int, float]:
    """Pixels where ``test`` is lit and ``reference (H, W, 3)`` exactly black, and their largest
    luminance relative to the reference's maximum."""
    yt, yr = test.astype(np.float64) @ LUM, reference.astype(np.float64) @ LUM
    m = (yt > 0) & (yr == 0)
    return int(m.sum()), float(yt[m].max() / yr.max()) if m.any() else 0.0


def run_setting(label: str, setting: dict, frames: dict) -> dict:
    """One row (see the module docstring)."""
    import study_glints_scenes as st

    import prefilter.glints.render as gr
    from prefilter.render.metrics import flip
    from prefilter.render.driver import render

    saved = dict(gr.BAKE_SETTINGS), gr.environment_radiance
    with contextlib.ExitStack() as stack:
        gr._SURFACES.clear()
        gr._BY_ID.clear()
        stack.callback(gr._SURFACES.clear)
        stack.callback(gr._BY_ID.clear)
        gr.BAKE_SETTINGS.update(setting)
        cache = gr.cache_dir()
        before = set(cache.glob("*.npz"))
        row = dict(label=label, setting=setting)
        t0 = time.perf_counter()
        render(_scene(CELLS[0]), "glints")
        row.update(first_frame_s=time.perf_counter() - t0,
                   baked=bool(set(cache.glob("*.npz")) - before))
        gm = next(s.gm for s in gr._SURFACES.values() if getattr(s, "gm", None) is not None)
        sm = gm.header["summary"]
        row.update(MB=sm["compressed_bytes"] / 1e6, rel_l2=sm["rel_l2_error"],
                   max_rank=sm["max_rank"], mean_rank=sm["mean_rank"])
        try:
            for c in CELLS:
                gr.environment_radiance = saved[1]
                if c[0] == "environment":
                    st._unprefiltered_environment()
                ref, hit, _ = frames[c]
                t0 = time.perf_counter()
                img = render(_scene(c), "glints")
                t = time.perf_counter() - t0
                f = flip(img, ref)
                fc = flip(img, ref, start_exposure=f.settings["start_exposure"],
                          stop_exposure=min(12.0, f.settings["stop_exposure"]))
                n, mx = leak(img, ref)
                row[_name(c)] = dict(flip=float(f.mean), flip_object=float(f.error_map[hit].mean()),
                                     capped=float(fc.mean),
                                     capped_object=float(fc.error_map[hit].mean()),
                                     leak=n, leak_max=mx, t_glints=t)
        finally:
            gr.BAKE_SETTINGS.clear()
            gr.BAKE_SETTINGS.update(saved[0])
            gr.environment_radiance = saved[1]
    return row


def table(rows: list[dict]) -> str:
    """Markdown: one row per setting; FLIP mid / far per cell (sphere: object pixels)."""
    out = ["| setting | first frame s | MB | rel L2 | max rank | point plane | point sphere | "
           "env plane | env sphere | capped +12: point plane / env plane | leak pixels "
           "(point plane, env plane; mid+far) | leak max |", "|---" * 12 + "|"]

    def pair(r, lt, sh, key):
        k = key + ("_object" if sh == "sphere" else "")
        return " / ".join(f"{r[f'{lt}_{sh}_{d}'][k]:.3f}" for d in ("mid", "far"))

    for r in rows:
        cells = [r[_name(c)] for c in CELLS]
        lk = [r[f"{lt}_plane_{d}"]["leak"] for lt in ("point", "environment")
              for d in ("mid", "far")]
        out.append(
            f"| {r['label']} | {r['first_frame_s']:.0f}{'' if r['baked'] else ' (cached)'} | "
            f"{r['MB']:.2f} | {r['rel_l2']:.2e} | {r['max_rank']} | "
            f"{pair(r, 'point', 'plane', 'flip')} | {pair(r, 'point', 'sphere', 'flip')} | "
            f"{pair(r, 'environment', 'plane', 'flip')} | "
            f"{pair(r, 'environment', 'sphere', 'flip')} | "
            f"{pair(r, 'point', 'plane', 'capped')}; {pair(r, 'environment', 'plane', 'capped')}"
            f" | {lk[0] + lk[1]}, {lk[2] + lk[3]} | {max(x['leak_max'] for x in cells):.1e} |")
    return "\n".join(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="glints_rank.jsonl", help="JSON lines, appended, resumed")
    ap.add_argument("--frames", default="glints_rank_frames",
                    help="folder of the glints-direct frames")
    ap.add_argument("--setting", action="append", default=None,
                    help="LABEL=JSON (repeatable); default: the module's DEFAULT_SETTINGS")
    ap.add_argument("--table", default=None, help="only print the table of this .jsonl")
    a = ap.parse_args()
    if a.table:
        print(table([json.loads(x) for x in Path(a.table).read_text().splitlines() if x]))
        return
    settings = DEFAULT_SETTINGS
    if a.setting:
        settings = {}
        for s in a.setting:
            label, sep, js = s.partition("=")
            if not sep:
                ap.error(f"--setting: expected LABEL=JSON, got {s!r}")
            settings[label] = json.loads(js)
    out = Path(a.out)
    done = {json.loads(x)["label"] for x in out.read_text().splitlines() if x} \
        if out.exists() else set()
    frames = direct_frames(Path(a.frames))
    for label, setting in settings.items():
        if label in done:
            continue
        row = run_setting(label, setting, frames)
        print(json.dumps(row), flush=True)
        with out.open("a") as fh:
            fh.write(json.dumps(row) + "\n")
    print(table([json.loads(x) for x in out.read_text().splitlines() if x]))


if __name__ == "__main__":
    main()
