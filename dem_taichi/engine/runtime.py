"""The one place that initialises Taichi (``ti.init``), idempotently.

``ensure_runtime(arch, precision)`` initialises Taichi on first use and re-initialises it
(``ti.reset`` then ``ti.init``) only when the arch or precision changes; every engine object
created under an earlier runtime is invalid after such a change.
``import dem_taichi`` never initialises Taichi.

arch: ``"cpu"`` (default) or ``"gpu"`` (CUDA; fails with a clear message when no GPU is usable).
precision: ``"f64"`` (default) or ``"f32"``: the default float type of every kernel and array.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

ARCHES = ("cpu", "gpu")
PRECISIONS = ("f64", "f32")


@dataclass(frozen=True)
class Runtime:
    arch: str
    precision: str
    generation: int  # increments at every (re-)initialisation

    @property
    def real(self):
        import taichi as ti

        return ti.f64 if self.precision == "f64" else ti.f32

    @property
    def numpy_real(self):
        import numpy as np

        return np.float64 if self.precision == "f64" else np.float32


_current: Runtime | None = None


def current_runtime() -> Runtime | None:
    return _current


_cuda_probe: bool | None = None


def cuda_available() -> bool:
    """True when Taichi can use a CUDA device (probed once in a subprocess; no side effects)."""
    global _cuda_probe
    if _current is not None and _current.arch == "gpu":
        return True
    if _cuda_probe is None:
        _cuda_probe = _probe_cuda()
    return _cuda_probe


def _probe_cuda() -> bool:
    import subprocess
    import sys

    code = (
        "import sys, taichi as ti\nti.init(arch=ti.cuda, log_level=ti.ERROR)\n"
        "sys.exit(0 if ti.cfg.arch == ti.cuda else 1)"
    )
    try:
        result = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return result.returncode == 0


def ensure_runtime(
    arch: str = "cpu", precision: str = "f64", cpu_threads: int | None = None
) -> Runtime:
    """Initialise Taichi for ``arch``/``precision`` unless it already is; return the runtime."""
    global _current
    if arch not in ARCHES:
        raise ValueError(f"arch = {arch!r}: allowed values are {' | '.join(ARCHES)}")
    if precision not in PRECISIONS:
        raise ValueError(f"precision = {precision!r}: allowed values are {' | '.join(PRECISIONS)}")
    if _current is not None and _current.arch == arch and _current.precision == precision:
        return _current
    import taichi as ti

    if _current is not None:
        ti.reset()
    real = ti.f64 if precision == "f64" else ti.f32
    kwargs = dict(default_fp=real, default_ip=ti.i32, log_level=ti.WARN, offline_cache=True)
    if arch == "cpu":
        threads = cpu_threads or int(os.environ.get("DEM_TAICHI_CPU_THREADS", "0")) or None
        if threads:
            kwargs["cpu_max_num_threads"] = threads
        ti.init(arch=ti.cpu, **kwargs)
    else:
        ti.init(arch=ti.cuda, **kwargs)
        if ti.cfg.arch != ti.cuda:
            ti.reset()
            _current = None
            raise RuntimeError(
                "arch='gpu' asked for but Taichi found no usable CUDA device; use arch='cpu'"
            )
    generation = 0 if _current is None else _current.generation + 1
    _current = Runtime(arch=arch, precision=precision, generation=generation)
    return _current
