"""three.js as a client of ``prefilter export-ltc --preset threejs``: a GGX plane under a
``RectAreaLight`` rendered by three.js (``clients/threejs``, three from npm, WebGL2 on
SwiftShader) with three's stock LTC tables and with the exported ones, each compared with the
project's Monte Carlo reference of the same scene (``tools/threejs_compare.py``). The exported
tables give the lower relative RMSE.

three's shader approximates the horizon clipping of the transformed polygon
(``LTC_ClippedSphereFormFactor``); at roughness 0.25 that approximation's error (about 5 %) hides
the tables' difference, so there the comparison runs with the polygon clipped
(``horizon="clip"``), as the shader does at every roughness in the second test. With clipping,
three.js with the exported tables matches the project's own ``ltc`` render.
"""

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]


def _compare_module():
    spec = importlib.util.spec_from_file_location("threejs_compare",
                                                  REPO / "tools" / "threejs_compare.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


tc = _compare_module()
W, H, SPP, SUPERSAMPLE = 48, 36, 1024, 2


@pytest.fixture(scope="module")
def client(browser, tmp_path_factory):
    """The browser with the client page open, served with freshly exported tables."""
    if not tc.THREE.is_file():
        pytest.skip(f"{tc.THREE} missing: run `make node_modules` "
                    "(cd clients/threejs && npm ci)")
    from prefilter.ltc.export import export_preset

    tables = tmp_path_factory.mktemp("threejs-tables")
    export_preset("threejs", tables)
    with tc.served_client(tables) as url:
        tc.open_client(browser, url)
        yield browser


@pytest.fixture(scope="module")
def rows(client):
    rows = tc.compare_open(client, (0.25, 0.5, 0.8), W, H, SPP, SUPERSAMPLE, extras=False)
    return {r["roughness"]: r for r in rows}


@pytest.mark.parametrize("roughness", [0.5, 0.8])
def test_exported_tables_beat_stock_in_threes_shader(rows, roughness):
    r = rows[roughness]
    assert r["images"]["reference"].mean() > 0.01  # the highlight is in the picture
    assert r["prefilter_sphere"] < r["stock_sphere"], r["channels"]


@pytest.mark.parametrize("roughness", [0.25, 0.5, 0.8])
def test_exported_tables_beat_stock_with_clipping(rows, roughness):
    r = rows[roughness]
    assert r["prefilter_clip"] < r["stock_clip"], r["channels"]


@pytest.mark.parametrize("roughness", [0.25, 0.5, 0.8])
def test_client_matches_project_ltc(client, roughness):
    """With the polygon clipped, the page with the exported tables renders the project's ``ltc``
    image (both at pixel centres): the client reads the tables as the project does (layout,
    half texel, matrix, Fresnel channels, radiance and camera conventions)."""
    from prefilter.render import render

    opts = tc.client_options(roughness, W, H)
    three = tc.render_three(client, opts, "prefilter", 1, "clip")
    ltc = render(tc.reference_scene(roughness, W, H), "ltc", spp=1)
    assert tc.rel_rmse(three, ltc) < 0.01
