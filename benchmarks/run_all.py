"""Run every benchmark in this folder (``make bench``) and collect their output.

Each ``bench_*.py`` is a standalone script that prints its measurements and, where it measures a
ratio, both timings from the same run (the machines are noisy, so ratios are the reportable number).
Results are also written to ``out/bench/<name>.txt``.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    out_dir = HERE.parent / "out" / "bench"
    out_dir.mkdir(parents=True, exist_ok=True)
    selected = set(sys.argv[1:])
    failed = []
    for script in sorted(HERE.glob("bench_*.py")):
        if selected and script.stem not in selected:
            continue
        print(f"== {script.stem}", flush=True)
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True)
        text = proc.stdout + (("\n" + proc.stderr) if proc.returncode else "")
        print(text, flush=True)
        print(f"   ({time.perf_counter() - t0:.1f} s)", flush=True)
        (out_dir / f"{script.stem}.txt").write_text(text)
        if proc.returncode:
            failed.append(script.stem)
    if failed:
        print("failed:", ", ".join(failed))
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
