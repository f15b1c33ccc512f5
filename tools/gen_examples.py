"""Write the shipped example scenes (src/prefilter/examples/*.json) from the code that builds them.

Each example is the scene of a demo section (``prefilter.report.demo`` and the method packages'
scene functions, at the demo's sizes) or the example of docs/scenes.md, so the files never drift
from what the demo renders. Run `python tools/gen_examples.py` after changing one of those scenes
(`--check` writes nothing and exits 1 when a file is out of date); tests/test_examples.py fails
while a file is out of date.
"""
import argparse
import json
import pathlib
import re
import sys

REPO = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "src"))

OUT = REPO / "src" / "prefilter" / "examples"
DOCS = REPO / "docs" / "scenes.md"


def docs_example() -> dict:
    """The first ```json block of docs/scenes.md."""
    block = re.search(r"```json\n(.*?)\n```", DOCS.read_text(encoding="utf-8"), re.S)
    return json.loads(block.group(1))


def scenes() -> dict:
    """name -> scene dict, one per entry of ``prefilter.examples.EXAMPLES``."""
    from prefilter.glints.render import measurement_scene
    from prefilter.ltc.aniso.demo import demo_scene
    from prefilter.report.demo import MULTISCALE_MAPS, DemoSettings, leadr_scene, showcase_scene
    from prefilter.report.pathtrace import kettle_scene, panel_scene, room_scene
    from prefilter.viewer.match import scene as match_scene

    s = DemoSettings()
    w, h = s.section_width, s.section_height
    far = 16.0 * h / 160.0  # the multi-scale section's far camera: ~16 texels per pixel
    return {
        "showcase": showcase_scene(1.0, s.width, s.height),
        "showcase-far": showcase_scene(16.0, s.width, s.height),
        "brushed-metal": demo_scene(w, h),
        "multiscale-brushed": showcase_scene(far, w, h, normal_map=MULTISCALE_MAPS["brushed"],
                                             alpha=0.03),
        "multiscale-flakes": showcase_scene(far, w, h, normal_map=MULTISCALE_MAPS["flakes"],
                                            alpha=0.03),
        "leadr": leadr_scene(w, h),
        "colormap": match_scene("colormap", w, h),
        "glints": measurement_scene(2.0, "flakes", s.glints_render_map, width=128, height=96),
        "plane-and-sphere": docs_example(),
        "kettle": kettle_scene(192, 128, 128),
        "flake-panel": panel_scene(192, 128, 128),
        "brushed-room": room_scene(192, 128, 128),
    }


def _plain(v):
    """JSON data with NumPy scalars as Python numbers (integral floats stay floats)."""
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if hasattr(v, "item"):
        return v.item()
    return v


def dumps(value, indent: int = 0) -> str:
    """JSON with one key per line and each list of numbers on one line (lists of lists too, when
    short)."""
    pad = " " * indent
    if isinstance(value, dict):
        items = [f'{pad}  {json.dumps(k)}: {dumps(v, indent + 2).lstrip()}'
                 for k, v in value.items()]
        return pad + "{\n" + ",\n".join(items) + "\n" + pad + "}"
    one_line = pad + json.dumps(value)
    if isinstance(value, list) and (any(isinstance(x, dict) for x in value)
                                    or len(one_line) > 90 and any(isinstance(x, list)
                                                                  for x in value)):
        return pad + "[\n" + ",\n".join(dumps(x, indent + 2) for x in value) + "\n" + pad + "]"
    return one_line


def generate() -> dict:
    """name -> file text."""
    return {name: dumps(_plain(sc)) + "\n" for name, sc in scenes().items()}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 if out of date")
    args = ap.parse_args()
    from prefilter.examples import EXAMPLES

    files = generate()
    assert list(files) == list(EXAMPLES), "tools/gen_examples.py and EXAMPLES list other names"
    stale = [n for n, text in files.items()
             if not (OUT / f"{n}.json").is_file()
             or (OUT / f"{n}.json").read_text(encoding="utf-8") != text]
    extra = sorted(p.name for p in OUT.glob("*.json") if p.stem not in files)
    if args.check:
        for n in stale:
            print(f"out of date: {OUT / n}.json")
        for n in extra:
            print(f"not an example: {OUT / n}")
        return 1 if stale or extra else 0
    from prefilter.report.pathtrace import write_assets

    write_assets(OUT)  # the meshes and sky the path-tracing examples read
    for n in stale:
        (OUT / f"{n}.json").write_text(files[n], encoding="utf-8")
        print(f"wrote {OUT / n}.json")
    for n in extra:
        (OUT / n).unlink()
        print(f"removed {OUT / n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
