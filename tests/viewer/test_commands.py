"""``prefilter export`` and ``prefilter view`` (click commands called directly) and the server."""

import json
import os
import signal
import subprocess
import sys
import urllib.request

import pytest
from click.testing import CliRunner

from prefilter.errors import PrefilterError
from prefilter.viewer import default_scene, serve
from prefilter.viewer.commands import export


def _scene_file(tmp_path):
    p = tmp_path / "scene.json"
    p.write_text(json.dumps(default_scene(64, 48)))
    return p


def test_export_writes_static_folder(tmp_path):
    res = CliRunner().invoke(export, [str(_scene_file(tmp_path)), "--out", str(tmp_path / "site"),
                                      "--no-builtin-maps"])
    assert res.exit_code == 0, res.output
    m = json.loads((tmp_path / "site/data/viewer.json").read_text())
    assert m["scene"]["camera"]["width"] == 64
    assert [x["name"] for x in m["maps"]] == ["scene: objects[0]"]


def test_export_bad_scene_is_an_error(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps({"camera": {}, "objects": []}))
    res = CliRunner().invoke(export, [str(p), "--out", str(tmp_path / "x")])
    assert res.exit_code != 0
    assert isinstance(res.exception, PrefilterError) and "camera" in str(res.exception)


def test_server_serves_modules_with_js_mime(tmp_path):
    CliRunner().invoke(export, [str(_scene_file(tmp_path)), "--out", str(tmp_path / "s"),
                                "--no-builtin-maps"])
    server, url = serve(tmp_path / "s")
    try:
        assert url.startswith("http://127.0.0.1:")
        with urllib.request.urlopen(url + "viewer.js") as r:
            assert r.headers["Content-Type"].startswith("text/javascript")
        with urllib.request.urlopen(url + "data/viewer.json") as r:
            assert json.loads(r.read())["version"] == 1
    finally:
        server.shutdown()
        server.server_close()


def test_serve_rejects_non_viewer_folder(tmp_path):
    with pytest.raises(PrefilterError, match="index.html"):
        serve(tmp_path)


def test_view_prints_url_and_serves(tmp_path):
    code = ("import sys; from prefilter.viewer.commands import view; "
            "view.main(sys.argv[1:], standalone_mode=True)")
    proc = subprocess.Popen([sys.executable, "-c", code, str(_scene_file(tmp_path)), "--port",
                             "0", "--no-browser"], stdout=subprocess.PIPE, text=True,
                            start_new_session=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("serving http://127.0.0.1:"), line
        url = line.split()[1]
        with urllib.request.urlopen(url + "index.html", timeout=10) as r:
            assert b"prefilter viewer" in r.read()
    finally:
        os.kill(proc.pid, signal.SIGINT)
        try:
            # 0.4 s on an idle machine; two full runs under load took more than 20 s here
            proc.wait(timeout=90)
        except subprocess.TimeoutExpired:
            proc.kill()
            raise AssertionError("the viewer did not end within 90 s of Ctrl-C") from None


def test_export_uses_the_given_table_file(tmp_path):
    """--iso-table: the exported texture holds that file's numbers (a table with every
    magnitude halved), not the shipped table's."""
    import numpy as np

    from prefilter.fileio import save_npz_atomic
    from prefilter.ltc.table import GGXTable

    t = GGXTable.load()
    p = tmp_path / "half.npz"
    save_npz_atomic(p, version=np.int64(1), axis_t=t.axis_t, axis_r=t.axis_r, M=t.M,
                    magnitude=0.5 * t.magnitude, fresnel=t.fresnel, settings=np.array("{}"))
    res = CliRunner().invoke(export, [str(_scene_file(tmp_path)), "--out", str(tmp_path / "s"),
                                      "--no-builtin-maps", "--iso-table", str(p)])
    assert res.exit_code == 0, res.output
    raw = np.fromfile(tmp_path / "s/data/ggx_iso_f32.bin", "<f4").reshape(
        3, len(t.axis_r), len(t.axis_t), 4)
    np.testing.assert_allclose(raw[2, 5, 7, 1], 0.5 * t.magnitude[7, 5], rtol=1e-6)
