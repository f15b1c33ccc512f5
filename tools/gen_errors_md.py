"""Write docs/errors.md from the PrefilterError / TableFileError raise sites (ast) plus notes.

Run `python tools/gen_errors_md.py` after adding or changing an error message (`--check` writes
nothing and exits 1 when the file is out of date); `tests/test_errors_doc.py` fails while
docs/errors.md is out of date.
"""
import argparse
import ast
import pathlib
import re
from collections import OrderedDict

REPO = pathlib.Path(__file__).resolve().parents[1]
ROOT = REPO / "src" / "prefilter"
DOC = REPO / "docs" / "errors.md"
ERRS = {"PrefilterError", "TableFileError"}


def render(node):
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        out = []
        for v in node.values:
            if isinstance(v, ast.Constant):
                out.append(v.value)
            else:
                e = v.value
                out.append(f"<{e.id}>" if isinstance(e, ast.Name) else "…")
        return "".join(out)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return render(node.left) + render(node.right)
    return f"<{node.id}>" if isinstance(node, ast.Name) else "…"


# (regex on the message, note); first match wins
RULES = [
    (r"checksum mismatch", "The file (or its sidecar) does not match the digest written at bake "
     "time: it is corrupt, truncated, edited by hand or comes from another bake. Re-run the bake "
     "(or restore the file); never edit baked files."),
    (r"meta_sha256", "The metadata was edited or damaged; re-bake."),
    (r"not found|no such file", "Wrong path, or the file was never baked: check the path; the "
     "message names the command that creates it where there is one."),
    (r"unreadable|corrupt|truncated|bad signature|no IHDR|not a PNG|nested too deeply|invalid "
     r"(JSON|TOML)|UTF-8", "The file cannot be parsed: it is damaged, truncated or not of the "
     "stated type. Re-export or re-bake it; for hand-written scene files fix the syntax at the "
     "position given."),
    (r"version|format: expected|\.format", "The file was written by another version or tool of "
     "the package; re-bake it with this version."),
    (r"missing array|missing arrays|unknown arrays|arrays: expected|required field is missing|"
     r"header field missing", "The file or scene lacks a field (or has extra ones): it is "
     "incomplete or from another layout. Re-bake, or add the field named in the message."),
    (r"unknown field|unknown parameter", "A misspelt or unsupported field/parameter; use one of "
     "those listed."),
    (r"do not broadcast|batch shapes|batch dimensions", "The leading (batch) dimensions of the "
     "named arguments are incompatible under NumPy broadcasting; reshape them (e.g. add axes of "
     "length 1) so they broadcast."),
    (r"finite", "A NaN or infinity reached the function, usually from a division by zero or an "
     "uninitialised pixel upstream; fix the producer (the value is never silently propagated)."),
    (r"unit vectors|unit length", "Directions must be normalised (|w| = 1 within the stated "
     "tolerance); a common bug is passing positions or un-normalised averages. Normalise first."),
    (r"above the surface|z > 0|z >= 0|n_z > 0|above the mean plane|horizon|blue >= 0.5",
     "Directions are in the local (tangent) frame, z = surface normal, and must lie in the "
     "upper hemisphere here. Transform to the local frame first; views below the surface are "
     "not meaningful for this function (lights below the horizon are accepted where noted)."),
    (r"symmetric", "Covariances must be symmetric 2x2 matrices; symmetrise ((C + C^T) / 2)."),
    (r"positive definite|positive semi-definite|eigenvalues", "Covariances must be (semi-)"
     "definite: variances > 0 and |c_xy| < sqrt(c_xx c_yy). Add a small base roughness "
     "(variance) to degenerate ones."),
    (r"invertible|singular|condition number", "LTC matrices must be invertible (condition "
     "number < 1e8); a singular matrix usually means an all-zero or collinear fit entry."),
    (r"roughness", "Roughness outside the supported range; clamp it to the range given."),
    (r"expected one of|expected '", "An option string outside the listed choices."),
    (r"expected a .*(Generator|integer seed)", "Random processes need an explicit seed or "
     "numpy Generator (determinism); None is refused."),
    (r"expected an integer|expected a positive integer", "Counts and sizes are Python/NumPy "
     "integers (not floats or bools) at least the bound given."),
    (r"expected (an |a )?(GlintsMap|ColormapTable|SlopeColormapTable|NoiseStd|MipChain|"
     r"GlintSurface|prefilter\.|moments MipChain|two-channel|one-channel)", "Pass the object "
     "built by the function named in the message (e.g. load() / prefilter_table() / "
     "moments_mip()), not a path or a raw array."),
    (r"expected shape|expected at least|channels|dimensions|expected a square|got shape",
     "The array layout is wrong: check the shape given after 'expected' ((..., 3) means any "
     "leading batch dimensions and a last axis of 3)."),
    (r"needs|not supported|unsupported|at most", "The method or tool does not support this "
     "combination; use one of the alternatives named in the message."),
    (r"in \[0, 1\]|\[0, 1\)", "Values must lie in [0, 1] (uniform random numbers, "
     "reflectances, colours)."),
    (r"numeric array", "Pass numbers (a list or NumPy array), not strings, None or objects."),
    (r"std|standard deviation|sigma|variance", "Standard deviations (footprint sizes, "
     "roughness, noise) must be >= 0 (> 0 where stated) and within the range given; a negative "
     "one usually comes from a variance E[x^2] - E[x]^2 made negative by rounding: clamp at 0."),
    (r"divisor|multiple|power of two|even ", "Sizes must tile: pick values that divide the map "
     "or resolution as stated (powers of two for mip chains)."),
    (r"light", "This method or viewer does not handle that kind of light, or the light's "
     "geometry is invalid (quads are convex, planar, given corner by corner); use a supported "
     "light or method as listed."),
    (r"quad|polygon", "The polygon is degenerate or passes through the shading point; it "
     "subtends no solid angle."),
    (r"same size|same shape|one shape|of each", "Compared images must have the same size and "
     "kind (both linear or both sRGB)."),
    (r"^[^ ]*: <exc>$|: <exc>$|^…: <exc>$", "Wraps a lower-level error with the file or "
     "field it concerns; the text after the colon explains it."),
    (r"expected a number|positive number|> 0|>= 0", "A number outside its valid range (or not a "
     "number); the message states the range."),
]

NOTES = {  # hand-written notes for specific patterns (substring of the rendered message)
    "the lobe is empty or nearly so": "The lobe's albedo is 0 or so small that exact "
    "rejection sampling would need more than 1e9 proposals (every reflection leaves below the "
    "horizon, e.g. a near-mirror mean surface tilted away from a grazing view). The BRDF is ~0 "
    "there: skip the view or use albedo().",
    "grid: expected the dict": "Pass the dict returned by convolution_grid (or one with the "
    "same keys).",
    ".checksum: expected 'sha256'": "The file's checksum entry is not in the package's format "
    "(another tool or version wrote it); re-bake.",
    "normal map: expected colours in [0, 1]": "Float colours must be in [0, 1]. The hint "
    "names the likely cause: 8/16-bit values stored as floats (divide by 255/65535, or pass the "
    "uint8/uint16 array itself) or normals already decoded to [-1, 1] (use them directly).",
    "expected 8- or 16-bit unsigned integers": "Integer normal maps must be uint8 or uint16 "
    "(8/16-bit files); other integer types are ambiguous.",
    "zero or downward vectors": "A colour decodes to a normal below the surface or to zero "
    "length: the image is not a tangent-space normal map (object-space map, height map, or the "
    "wrong green convention with a damaged blue channel). The first bad texel is named.",
    "convention: expected one of": "Normal-map green convention: 'opengl' (Y+, Blender, Maya) or"
    " 'directx' (Y-, Unreal, 3ds Max). A wrong choice mirrors bumps vertically (no error can "
    "detect it); check a known bump.",
    "the lobe is empty": "The view sees only the back of the mean (tilted) surface: G1 = 0, "
    "so there is no lobe to sample. Skip such views (their BRDF is 0).",
    "expected at least one direction above the horizon": "Maximum-likelihood roughness needs "
    "samples with m_z > 0 in every batch entry; an empty set has no estimate (it used to "
    "return 2 silently).",
    "elements_:": "Pass exactly the pair returned by elements(normal_map) for that map.",
    "s_max: expected s_max > s_min": "Range queries need non-empty rectangles.",
    "pdf: expected finite densities": "The density passed to chi2_sphere returned NaN, inf or "
    "a negative value at some direction: fix the pdf (a NaN used to give a NaN p-value).",
    "expected indices in [0": "block_means takes flat pyramid image indices of the map.",
    "the glints map was baked from": "The normal map differs from the one the glints map was "
    "baked from; pass the same map or re-bake.",
    "sample_lobe: roughness parameters must be scalars": "sample_lobe draws from one lobe; "
    "build the model with scalar roughness.",
    "cot_theta: expected cotangents > 0": "Directions at or below the horizon have no Smith "
    "Lambda in this form; use height_distribution, which treats such lights as unlit.",
    "noise_sigma: expected a std >= 0": "Standard deviations are >= 0.",
    "value_range: expected (lo, hi)": "The value range of the colour map, with lo < hi.",
    "r: expected lengths in [0, 1]": "The length of an averaged unit normal is at most 1 (up to "
    "1e-6 rounding); longer vectors mean the normals were not unit length.",
    "PyTorch": "Install the optional fit dependencies: pip install 'prefilter[fit]'.",
    "more than the memory budget": "The request (image size x samples per pixel, map size, "
    "table size) would need more memory than the budget: by default half the machine's memory, "
    "or PREFILTER_MEMORY_BUDGET (bytes, or 8G, 512M). Ask for less, or raise the budget if the "
    "machine has the memory.",
    "(the scene domain)": "Scene magnitudes have a documented domain (docs/scenes.md, Ranges): "
    "coordinates and lengths up to 1e6, uv_scale up to 1e6, light values up to 1e12. Rescale "
    "the scene's units.",
}

MODULE_TITLES = OrderedDict([
    ("validation.py", "Shared validators (prefilter.validation): used by every module"),
    ("fileio.py", "Baked files (prefilter.fileio): .npz tables and maps with checksums"),
])


def note_for(msg, cls, rel=""):
    if rel == "render/scene.py" and msg.startswith("…:"):
        return ("A scene-file field, named in the message by its path in the file (e.g. "
                "`scene.json: objects[2].material.alpha`), has the wrong type or value; fix the "
                "scene file (docs/scenes.md lists the fields).")
    for k, v in NOTES.items():
        if k in msg:
            return v
    for pat, text in RULES:
        if re.search(pat, msg):
            return text
    if cls == "TableFileError":
        return "The file does not have the expected layout; re-bake it with this version."
    return "Self-describing: pass what the message states after 'expected' (see the common " \
           "causes above)."


def esc(s):
    return s.replace("|", "\\|").replace("\n", " ")


def generate() -> str:
    """The text of docs/errors.md for the current source."""
    rows = []
    for path in sorted(ROOT.rglob("*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call):
                f = node.func
                name = f.id if isinstance(f, ast.Name) else (
                    f.attr if isinstance(f, ast.Attribute) else None)
                if name in ERRS and node.args:
                    rel = str(path.relative_to(ROOT))
                    rows.append((rel, node.lineno, name, render(node.args[0])))
    groups = OrderedDict()
    for rel, line, cls, msg in sorted(rows, key=lambda r: (r[0] != "validation.py",
                                                           r[0] != "fileio.py", r[0], r[1])):
        if rel == "errors.py":
            continue
        seen = groups.setdefault(rel, OrderedDict())
        seen.setdefault((cls, msg), line)
    out = [HEADER]
    for rel, msgs in groups.items():
        mod = "prefilter." + rel[:-3].replace("/", ".").replace(".__init__", "")
        out.append(f"\n### `{mod}`\n")
        out.append("| Message (`<name>`: a parameter or path; `…`: the value received) | Type | "
                   "Meaning and what to do |")
        out.append("|---|---|---|")
        for (cls, msg), line in msgs.items():
            t = "TableFileError" if cls == "TableFileError" else "PrefilterError"
            out.append(f"| `{esc(msg)}` | {t} | {esc(note_for(msg, cls, rel))} |")
    n = sum(len(m) for m in groups.values())
    out.append(f"\n_{n} message patterns in {len(groups)} modules._\n")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description="Write docs/errors.md from the package's raise "
                                 "sites (or, with --check, only say whether it is current).")
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 if docs/errors.md is out of date")
    args = ap.parse_args(argv)
    text = generate()
    if args.check:
        current = DOC.read_text() if DOC.exists() else ""
        print(f"{DOC}: {'up to date' if current == text else 'out of date'}")
        return 0 if current == text else 1
    DOC.write_text(text)
    print(f"wrote {DOC}")
    return 0


HEADER = """# Error messages

Every invalid input to a public function, file or command raises one exception type of the
package, `prefilter.errors.PrefilterError` (a `ValueError`), or its subclass `TableFileError` for
files (tables, baked maps, images, scene files). Nothing else is raised for bad input, and no
function returns NaN for it. The command line prints the message on one line and exits with
code 2.

Messages follow one pattern:

    <parameter, or file: field>: expected <what is accepted>, got <what was received>

so the part before the colon says *where* (a parameter name such as `wo`, `alpha_x`,
`slope_cov`, or a path and the field inside the file), and the rest says *what to pass*. Array
values are printed in full when small, by shape when large. Shapes use NumPy's notation:
`(..., 3)` is any number of leading batch dimensions and a last axis of length 3; batch
dimensions of different arguments broadcast against each other.

Catching them:

```python
from prefilter.errors import PrefilterError, TableFileError

try:
    table = AnisoGGXTable.load(path)
except TableFileError as err:      # a file problem: re-bake or restore the file
    ...
except PrefilterError as err:      # any other bad input
    ...
```

## Common causes

| Symptom in the message | Cause and fix |
|---|---|
| `expected finite values, got NaN or inf` | A NaN or inf was produced upstream (division by zero, an empty footprint, an uninitialised pixel). Fix the producer. |
| `expected unit vectors (\\|w\\| = 1 within 0.001)` | Directions must be normalised. Averaged normals (mip maps) are shorter than 1: normalise them, or use the functions that take their length on purpose (`mean_resultant_length`, `alpha_meso`). |
| `expected directions above the surface (z > 0)` | Directions are in the local frame (z = normal). A view below the surface is refused where it has no meaning; lights below the horizon are accepted and give 0 (LEADR `point_light`, colour-map `height_distribution`). |
| `expected roughness in [0.0001, 4.0]` | GGX/Beckmann `alpha`. Perfect mirrors (0) are not microfacet lobes: use 1e-4. |
| `normal map: expected colours in [0, 1] ... divide by 255 / 65535` | 8/16-bit data passed as floats. Pass the `uint8`/`uint16` array (it is scaled) or divide. |
| `normal map: ... already decoded normals in [-1, 1]?` | The array already holds normals, not colours: skip `decode_normals`. |
| `normal map: expected tangent-space normals with z >= 0 (blue >= 0.5)` | Not a tangent-space normal map (object-space map, a height map, a mask). |
| DirectX vs OpenGL green | No error can detect it: a map decoded with the wrong `convention` has its bumps mirrored vertically (lit from below). `prefilter` uses OpenGL (Y+) by default; pass `convention="directx"` for Unreal / 3ds Max maps. |
| `batch shapes do not broadcast` | The leading dimensions of two arguments are incompatible; add axes of length 1 or tile one of them. |
| `checksum mismatch` | A baked file or its sidecar changed after baking (corruption, truncation, hand edit). Re-bake; the bake commands are resumable and deterministic. |
| `version: expected 1, got 2` / `format: expected ...` | The file comes from another version of the package or another tool. |

## All messages, by module

The tables list every message pattern raised by the package (generated from the source: each
`raise PrefilterError(...)` / `TableFileError(...)`, with f-string fields shown as `<name>` or
`…`), with what it means and what to do.
"""  # noqa: E501 -- markdown table rows cannot be wrapped

if __name__ == "__main__":
    raise SystemExit(main())
