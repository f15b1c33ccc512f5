"""``prefilter cache``: every on-disk cache listed with its path and size, cleared by name."""

import pytest
from click.testing import CliRunner

from prefilter import cache
from prefilter.cache import cache_command
from prefilter.errors import PrefilterError


@pytest.fixture
def caches(tmp_path, monkeypatch):
    """Both caches in a temporary folder, with a file each."""
    g, n = tmp_path / "glints", tmp_path / "numba"
    monkeypatch.setenv("PREFILTER_GLINTS_CACHE", str(g))
    monkeypatch.setenv("PREFILTER_NUMBA_CACHE", str(n))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    (g / "x.npz.parts").mkdir(parents=True)
    (g / "x.npz.parts" / "level0.npy").write_bytes(b"\1" * 5000)
    (g / "m.npz").write_bytes(b"\1" * 3000)
    (n / "0123456789abcdef").mkdir(parents=True)
    (n / "0123456789abcdef" / "k.nbc").write_bytes(b"\1" * 100)
    return g, n


def test_list_names_every_cache_with_path_and_size(caches):
    g, n = caches
    by_name = {c.name: c for c in cache.caches()}
    assert set(by_name) == {"glints", "numba"}
    assert by_name["glints"].path == g and by_name["glints"].files == 2
    assert by_name["glints"].size >= 8000
    assert by_name["numba"].path == n and by_name["numba"].files == 1
    res = CliRunner().invoke(cache_command, [])
    assert res.exit_code == 0, res.output
    assert str(g) in res.output and str(n) in res.output and "KiB" in res.output
    assert CliRunner().invoke(cache_command, ["list"]).output == res.output


def test_clear_one_cache_or_all(caches):
    g, n = caches
    res = CliRunner().invoke(cache_command, ["clear", "glints"])
    assert res.exit_code == 0, res.output
    assert "glints: removed" in res.output and "2 files" in res.output
    assert g.is_dir() and not any(g.iterdir())
    assert any(n.iterdir())
    res = CliRunner().invoke(cache_command, ["clear"])
    assert res.exit_code == 0 and "numba: removed" in res.output
    assert not any(n.iterdir())


def test_unknown_cache_is_named(caches):
    with pytest.raises(PrefilterError, match="NAME: expected one of"):
        cache.clear("nope")


def test_registered_in_the_cli():
    from prefilter.cli import TOP_COMMANDS

    assert TOP_COMMANDS["cache"] == "prefilter.cache:cache_command"
