"""Environment lights: does the trilinear pyramid blend of ``glints``' range queries bias them,
as it did for quad lights (issue #9)? Plane at mid distance, ``glints`` averaged over ``--seeds``
seeds with ``envlight.RANGE_INTERP`` trilinear and resample, FLIP against the deterministic
``matched`` and ``converged`` references (:mod:`prefilter.glints.reference`); one JSON row per map.

    python benchmarks/study_glints_env_interp.py --kinds flakes,gaussian
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))


def study(kind: str, seeds: int = 32) -> dict:
    """One map: FLIP (frame, object) of ``glints`` averaged over 1 / 4 / ``seeds`` seeds vs the
    references, per range-weight interpolation, and CPU seconds per frame."""
    import study_glints_scenes as st

    from prefilter.glints import envlight
    from prefilter.glints.reference import render_converged
    from prefilter.render.driver import render
    from prefilter.render.scene import load_scene

    sc = load_scene(st.scene("plane", st.DISTANCES["mid"], kind, "environment"))
    render(sc, "glints")  # bake and compile outside the timing
    _, hit = st.coverage(sc)
    t0 = time.process_time()
    matched = render_converged(sc, matched=True)
    row = {"map": kind, "cpu_matched": time.process_time() - t0}
    conv = render_converged(sc)
    saved = envlight.RANGE_INTERP
    try:
        for interp in ("trilinear", "resample"):
            envlight.RANGE_INTERP = interp
            render(sc, "glints", seed=0)
            t0 = time.process_time()
            imgs = [render(sc, "glints", seed=k) for k in range(seeds)]
            row[f"cpu_{interp}"] = (time.process_time() - t0) / seeds
            for n in (1, 4, seeds):
                g = np.mean(imgs[:n], 0)
                row[f"{interp}_{n}_matched"] = st._flip_pair(g, matched, hit)
                row[f"{interp}_{n}_converged"] = st._flip_pair(g, conv, hit)
            row[f"{interp}_mean_matched"] = float(np.mean(imgs) / matched.mean())
    finally:
        envlight.RANGE_INTERP = saved
    return row


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kinds", default="flakes,gaussian")
    ap.add_argument("--seeds", type=int, default=32)
    a = ap.parse_args()
    for kind in a.kinds.split(","):
        print(json.dumps(study(kind, a.seeds)), flush=True)


if __name__ == "__main__":
    main()
