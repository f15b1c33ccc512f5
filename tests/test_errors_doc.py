"""docs/errors.md lists every error message the package raises (regenerate with
`python tools/gen_errors_md.py`)."""

import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_errors_doc_is_current():
    spec = importlib.util.spec_from_file_location("gen_errors_md",
                                                  REPO / "tools" / "gen_errors_md.py")
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    current = (REPO / "docs" / "errors.md").read_text()
    assert gen.generate() == current, (
        "docs/errors.md is out of date: run `python tools/gen_errors_md.py`")
