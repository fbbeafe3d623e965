"""Run every benchmark (not tests): each prints its table and saves it under benchmarks/results/.

Usage::

    python benchmarks/run_all.py [--quick]

``--quick`` passes the scripts' short modes (minutes); without it the full tables are measured
(the DEM paper-size and probe benchmarks take tens of minutes on a 2-core CPU).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def commands(quick: bool) -> list[list[str]]:
    python = sys.executable
    return [
        [python, str(HERE / "bench_tiv.py")] + (["--quick"] if quick else []),
        [python, str(HERE / "bench_dem.py")] + (["--quick"] if quick else []),
        [python, str(HERE / "bench_protocol.py")] + (["smoke"] if quick else ["default", "paper"]),
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short modes of every benchmark")
    args = parser.parse_args(argv)
    failed = []
    for command in commands(args.quick):
        print(f"\n$ {' '.join(Path(c).name if c.endswith('.py') else c for c in command)}")
        if subprocess.run(command, check=False).returncode != 0:
            failed.append(Path(command[1]).name)
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
