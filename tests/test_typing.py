"""mypy over the non-kernel code is clean, with the configuration of ``pyproject.toml``
(``[tool.mypy]``: the packages, scripts and benchmarks; not the Taichi kernels).

``make lint`` runs mypy too, but CI runs ``make test`` only: this test is what keeps the code
typed there. mypy's cache goes to the test's temporary folder, so every run checks from cold as
a fresh clone does (measured: ~16 s of one core; ~45 s beside a running simulation on 2 cores).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_mypy_is_clean(tmp_path):
    result = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(tmp_path / "mypy_cache")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=900,
    )
    output = result.stdout + result.stderr
    assert result.returncode == 0, f"mypy found errors (`make lint` shows them too):\n{output}"
    # a configuration section that matches no module is a stale or misspelt module name
    assert "unused section" not in output, output
