"""Run every ``benchmarks/bench_*.py`` script in turn (``make bench``).

Each script writes its CSV and PNG into ``benchmarks/results/``, prints a Markdown table and
rewrites its tables in ``benchmarks/README.md`` (``benchmarks/_tables.py``).
A failing script is reported and the others still run; the exit status is non-zero if any
failed.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent


def main() -> int:
    scripts = sorted(HERE.glob("bench_*.py"))
    failed = []
    for script in scripts:
        print(f"\n=== {script.name}", flush=True)
        t0 = time.perf_counter()
        rc = subprocess.call([sys.executable, str(script)], cwd=HERE.parent)
        print(f"=== {script.name}: exit {rc} after {time.perf_counter() - t0:.0f} s", flush=True)
        if rc:
            failed.append(script.name)
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
