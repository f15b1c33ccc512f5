"""Invalid numbers given to the bakes are refused before any work: exit code 2, nothing written.

NaN is the case ``click.FloatRange`` lets through (every comparison with NaN is false); zero
counts, negative seeds and infinities are the others. Each case runs the CLI in-process.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from prefilter.cli import main
from prefilter.errors import PrefilterError

ISO = ["bake", "ltc-iso", "--res", "3", "--samples", "6", "--quiet"]
ANISO = ["bake", "ltc-aniso", "--res", "2", "--steps", "2", "--quiet"]
GLINTS = ["bake", "glints", "procedural:gaussian:32", "--ndf-res", "16", "--block", "8",
          "--rank", "2", "--quiet"]
WANG = ["bake", "glints-wang", "procedural:gaussian:32", "--tile", "16", "--quiet"]
CMAP = ["bake", "colormap", "{ramp}", "--size", "8"]
LEADR = ["bake", "leadr", "{height}"]

CASES = {
    "iso-power-nan": (ISO + ["--power", "nan"], "power"),
    "iso-power-inf": (ISO + ["--power", "inf"], "power"),
    "iso-seed-negative": (ISO + ["--seed", "-1"], "seed"),
    "iso-res-1": (ISO[:3] + ["1"] + ISO[4:], "res"),
    "aniso-seed-negative": (ANISO + ["--seed", "-1"], "seed"),
    "aniso-steps-0": (ANISO[:5] + ["0"] + ANISO[6:], "steps"),
    "glints-iters-0": (GLINTS + ["--iters", "0"], "iters"),
    "glints-converge-nan": (GLINTS + ["--converge", "nan"], "converge"),
    "glints-converge-negative": (GLINTS + ["--converge", "-1"], "converge"),
    "glints-blank-tol-nan": (GLINTS + ["--blank-tol", "nan"], "blank-tol"),
    "glints-sigma0-nan": (GLINTS + ["--sigma0", "nan"], "sigma0"),
    "glints-support-inf": (GLINTS + ["--support", "inf"], "support"),
    "glints-roughness-nan": (GLINTS + ["--roughness", "nan"], "roughness"),
    "glints-truncation-nan": (GLINTS + ["--ndf-truncation", "nan"], "ndf-truncation"),
    "glints-rank-0": (GLINTS[:-2] + ["0", "--quiet"], "rank"),
    "glints-seed-negative": (GLINTS + ["--seed", "-1"], "seed"),
    "wang-band-nan": (WANG + ["--band", "nan"], "band"),
    "wang-wide-tiles-0": (WANG + ["--wide-tiles", "0"], "wide-tiles"),
    "wang-iters-0": (WANG + ["--iters", "0"], "iters"),
    "colormap-sigma-max-nan": (CMAP + ["--sigma-max", "nan"], "sigma_max"),
    "colormap-sigma-max-inf": (CMAP + ["--sigma-max", "inf"], "sigma_max"),
    "colormap-sigma-max-0": (CMAP + ["--sigma-max", "0"], "sigma_max"),
    "colormap-range-nan": (CMAP + ["--sigma-max", "0.1", "--range", "nan", "1"], "value_range"),
    "leadr-texel-size-nan": (LEADR + ["--texel-size", "nan"], "texel_size"),
    "leadr-texel-size-0": (LEADR + ["--texel-size", "0"], "texel_size"),
    "leadr-base-roughness-inf": (LEADR + ["--base-roughness", "inf"], "base_roughness"),
    "multiscale-fit-grid-1": (["multiscale-fit", "--grid", "1"], "grid"),
    "multiscale-fit-samples-0": (["multiscale-fit", "--samples", "0"], "samples"),
}


@pytest.fixture
def inputs(tmp_path):
    from prefilter.texture.io import write_image

    x = np.linspace(0, 1, 16)
    ramp = write_image(tmp_path / "ramp.png", np.stack([x, x**2, 1 - x], -1)[None], bits=16)
    height = write_image(tmp_path / "height.exr", np.random.default_rng(1).normal(size=(8, 8)))
    return {"ramp": str(ramp), "height": str(height)}


@pytest.mark.parametrize("case", list(CASES))
def test_invalid_bake_number_is_refused_before_work(case, inputs, tmp_path, capsys):
    args, name = CASES[case]
    out = tmp_path / "out"
    args = [a.format(**inputs) for a in args]
    if args[0] == "bake":
        args += ["-o", str(out.with_suffix(".png" if "colormap" in args else ".npz"))
                 if "leadr" not in args else str(out)]
    with pytest.raises(SystemExit) as exit_:
        main(args)
    err = capsys.readouterr().err
    assert exit_.value.code == 2, err
    assert name in err or name.replace("-", "_") in err, err
    assert "Traceback" not in err
    assert not [p for p in tmp_path.iterdir() if p.name.startswith("out")], "a file was written"


def test_library_fit_settings_refuse_invalid_numbers():
    from prefilter.ltc.fit_iso import FitSettings

    for kwargs in ({"power": math.nan}, {"power": 0.0}, {"n_fit": 0}, {"seed": -1},
                   {"alpha_min": math.nan}, {"theta_max_deg": 90.0}, {"res_theta": 1}):
        with pytest.raises(PrefilterError, match=next(iter(kwargs))):
            FitSettings(**kwargs)
