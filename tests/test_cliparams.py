"""``prefilter.cliparams``: the seed type and the writability check of output paths."""

from __future__ import annotations

import os

import click
import pytest

from prefilter.cliparams import SEED, SEED_MAX, OutputDir, OutputFile, check_writable
from prefilter.errors import PrefilterError


def test_check_writable_accepts_new_files_and_folders(tmp_path):
    assert check_writable(tmp_path / "a.exr") == tmp_path / "a.exr"
    assert check_writable(tmp_path / "new" / "deeper" / "a.exr")
    assert check_writable(tmp_path / "out", directory=True)
    (tmp_path / "a.exr").write_bytes(b"x")
    check_writable(tmp_path / "a.exr")  # replaced atomically
    assert sorted(os.listdir(tmp_path)) == ["a.exr"]  # the probe files are gone


@pytest.mark.parametrize("path,directory,words", [
    ("/dev/null/x.exr", False, "/dev/null is not a folder"),
    ("/proc/x.exr", False, "/proc does not accept new files"),
    ("/proc/sub/dir", True, "/proc does not accept new files"),
    ("{tmp}", False, "it is a folder"),
    ("{tmp}/f.txt", True, "it is a file"),
    ("{tmp}/f.txt/x.exr", False, "f.txt is not a folder"),
])
def test_check_writable_names_the_path(tmp_path, path, directory, words):
    (tmp_path / "f.txt").write_text("x")
    path = path.format(tmp=tmp_path)
    with pytest.raises(PrefilterError) as exc:
        check_writable(path, directory=directory)
    assert str(exc.value).startswith(f"{path}: cannot write"), exc.value
    assert words in str(exc.value)


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes through permission bits")
def test_check_writable_read_only_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(PrefilterError, match="does not accept new files"):
            check_writable(ro / "x.exr")
    finally:
        ro.chmod(0o700)


@pytest.mark.parametrize("value,expected", [("0", 0), ("17", 17), (5, 5),
                                            (str(SEED_MAX), SEED_MAX)])
def test_seed_accepts(value, expected):
    assert SEED.convert(value, None, None) == expected


@pytest.mark.parametrize("value", ["-1", -3, str(SEED_MAX + 1), "1.5", "x", ""])
def test_seed_refuses(value):
    with pytest.raises(click.BadParameter, match="seed"):
        SEED.convert(value, None, None)


def test_output_types_fail_as_bad_parameters(tmp_path):
    with pytest.raises(click.BadParameter, match="/dev/null/x"):
        OutputFile().convert("/dev/null/x", None, None)
    with pytest.raises(click.BadParameter, match="/proc/x"):
        OutputDir().convert("/proc/x", None, None)
    assert OutputFile().convert(str(tmp_path / "x.exr"), None, None) == str(tmp_path / "x.exr")
