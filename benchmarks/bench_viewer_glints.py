"""Frame time of the viewer's ``glints`` mode in headless Chromium (WebGL2 on SwiftShader) at
512 x 512 per distance of the glints measurement plane, and the max / min ratio over the
distances (the constant-cost claim on the GPU path).

    python benchmarks/bench_viewer_glints.py [--kind flakes] [--size 512] [--frames 3]
        [--rounds 3] [--codes f32] [--distances near,mid,far]

The 64^2 built-in map is baked on first use (``$PREFILTER_GLINTS_CACHE``). Rounds interleave
the distances; the best of the rounds is reported, with the share of the pixels each path
shades (direct P-NDF below the finest level, resampled level, trilinear top levels) and the
median footprint std. ``--distances`` takes names of ``DISTANCES`` and numbers (the scene
scaled: at 512 x 512, distances of 32 and more put the footprints on the compressed pyramid).
"""

import argparse

from prefilter.viewer.glints import DISTANCES, GLINT_MAPS, glints_frame_times, glints_paths


def _distance(x: str):
    return x if x in DISTANCES else float(x)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--kind", default="flakes", choices=sorted(GLINT_MAPS))
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--frames", type=int, default=3)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--codes", default="f32", choices=("f32", "f16", "u8"))
    ap.add_argument("--distances", default=",".join(DISTANCES))
    a = ap.parse_args()
    ds = tuple(_distance(x) for x in a.distances.split(","))
    t = glints_frame_times(a.kind, ds, width=a.size, height=a.size, frames=a.frames,
                           rounds=a.rounds, codes=a.codes)
    for d, ms in t.items():
        p = glints_paths(a.kind, d, a.size, a.size)
        print(f"  {str(d):5s} (distance {DISTANCES.get(d, d):g}): {ms:9.1f} ms  direct "
              f"{p['direct']:.0%} resampled {p['resampled']:.0%} trilinear {p['trilinear']:.0%}"
              f" median sigma {p['median_sigma']:.2f} texels")
    print(f"max/min over distances: {max(t.values()) / min(t.values()):.2f}")


if __name__ == "__main__":
    main()
