"""The regression tests pass on another CPU: the smoke references under other SIMD/BLAS kernels.

The smoke references (``tests/data/smoke_protocol_*reference.npz``) were recorded on an AMD
EPYC machine and must pass on any x86-64 or ARM machine with the pinned dependencies. They hold
the trajectory bit for bit and the reductions to a stated tolerance
(:data:`tests.dem_taichi.test_protocol.REDUCTION_RTOL`, which says why). A second CPU is not at
hand in a test, so this one changes what the numeric libraries dispatch on *this* CPU: numpy's
SIMD kernels limited to its build baseline (``NPY_DISABLE_CPU_FEATURES`` = every dispatched
feature group, e.g. X86_V3/X86_V4/AVX512 on x86-64) and OpenBLAS forced onto another core's
kernels (``OPENBLAS_CORETYPE``: Katmai's SSE kernels on x86-64, the generic ARMV8 ones on
ARM). The reference tests then run in a fresh interpreter (numpy and OpenBLAS read these at
import). What cannot be changed this way is Taichi's own code generation, which targets the
host CPU: that difference (AVX-512 vs AVX2 ordering of vectorised sums) is what the tolerance
on reductions covers, measured on an Intel Xeon against the EPYC reference. Where the
difference reaches the trajectory (on an EPYC with AVX-512 the servo feeds the stresses' last
bits back into the loading), the host keeps its own references and the reference tests use
them (``tests.dem_taichi.test_protocol.codegen_host``); without one, they are skipped outside CI
when the run departs from the default reference as rounding only.
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _other_kernels_environment() -> dict[str, str]:
    """This environment with numpy's dispatched SIMD features off and OpenBLAS on another
    core's kernels (module docstring)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    env = dict(os.environ)
    available = [name for name in __cpu_dispatch__ if __cpu_features__.get(name)]
    if available:
        env["NPY_DISABLE_CPU_FEATURES"] = " ".join(available)
    machine = platform.machine().lower()
    env["OPENBLAS_CORETYPE"] = "ARMV8" if machine in ("aarch64", "arm64") else "Katmai"
    env["OPENBLAS_VERBOSE"] = "2"  # OpenBLAS prints the core it runs on: checked below
    return env


def test_the_changed_setting_takes_effect():
    """The subprocess really runs other kernels: numpy reports the dispatched groups off and
    OpenBLAS names the forced core."""
    env = _other_kernels_environment()
    code = (
        "from numpy._core._multiarray_umath import __cpu_dispatch__ as d, __cpu_features__ as f\n"
        "import scipy.linalg\n"
        "print('on:', [k for k in d if f.get(k)])\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120
    )
    assert done.returncode == 0, done.stderr
    assert "on: []" in done.stdout
    assert f"Core: {env['OPENBLAS_CORETYPE']}" in done.stderr


def _reference_test_under_other_kernels(tmp_path: Path, name: str) -> None:
    """Run the reference test ``name`` of tests/dem_taichi/test_protocol.py in a fresh
    interpreter running numpy's baseline kernels and another OpenBLAS core."""
    command = [
        sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "no:xdist",
        f"tests/dem_taichi/test_protocol.py::{name}",
        "--basetemp", str(tmp_path / "pytest"),
    ]  # fmt: skip
    env = _other_kernels_environment()
    env.pop("DEM_RECORD_REFERENCE", None)  # never overwrite the references from here
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=900)
    tail = (done.stdout + done.stderr)[-3000:]
    assert done.returncode == 0, tail
    assert "1 passed" in done.stdout, tail


def test_secant_smoke_reference_passes_under_other_simd_and_blas_kernels(tmp_path):
    """The secant-servo smoke reference (the servo of the shipped protocol scenes but ``default``
    and ``demo``) passes under other SIMD and BLAS kernels, its history included (about 20 s: one
    smoke protocol). The servo's gain algebra, where BLAS once changed the trajectory, is the
    same code for both servos' references."""
    _reference_test_under_other_kernels(tmp_path, "test_secant_smoke_outputs_equal_the_reference")


@pytest.mark.slow
def test_smoke_reference_passes_under_other_simd_and_blas_kernels(tmp_path):
    """The elastic-servo smoke reference, likewise (make test-slow: its protocol takes 2.3x the
    secant one's steps)."""
    _reference_test_under_other_kernels(tmp_path, "test_smoke_outputs_equal_the_reference")
