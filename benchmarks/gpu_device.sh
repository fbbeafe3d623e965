#!/usr/bin/env bash
# The GPU measurement of benchmarks/results/gpu_bench.md, as run on a lent device machine (one
# NVIDIA H200, Python 3.12 with numpy/scipy/xarray/matplotlib, no network): Taichi and the few
# packages the machine lacks travel in .gpu/ (ignored by git), with the 1520-rod packing the
# cases tile (bench_gpu.py prepare). Writes its logs and rows under $OUT.
#
#   .gpu/taichi312.tar.xz   Taichi 1.7.4 for CPython 3.12 (the wheel unpacked, less its C API
#                           library and examples, xz-compressed to fit the 64 MiB transfer)
#   .gpu/*.whl              netCDF4, cftime, dill, pint (+ flexcache, flexparser, platformdirs)
#   .gpu/gpu_state.npz      bench_gpu.py prepare --out .gpu/gpu_state.npz
# benchmarks/gpu_pack.sh builds all three here.
set -u
OUT=${OUT:-/tmp/gpu_out}
mkdir -p "$OUT" /tmp/site
t0=$(date +%s)
tar -xJf .gpu/taichi312.tar.xz -C /tmp/site
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site \
    .gpu/*.whl 2>&1 | grep -v WARNING
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
{
    nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.max.sm --format=csv
    nproc; python3 --version; python3 -c "import numpy, taichi; print(numpy.__version__)"
    echo "set-up $(($(date +%s) - t0)) s"
} 2>&1 | tee "$OUT/env.txt"
DEADLINE=${DEADLINE:-510}  # seconds for the whole script
timeout 150 python3 -m pytest -q -p no:cacheprovider -n 3 -m gpu \
    tests/dem_taichi/test_engine_precision.py tests/dem_taichi/test_parallel_lists.py \
    tests/dem_taichi/test_parallel_measures.py \
    2>&1 | tail -15 | tee "$OUT/pytest.log"
left=$((DEADLINE - ($(date +%s) - t0)))
echo "tests done at $(($(date +%s) - t0)) s; $left s left for the suite"
timeout "$left" python3 benchmarks/bench_gpu.py suite \
    --state .gpu/gpu_state.npz --out "$OUT" --budget $((left - 20)) --plan "${PLAN:-full}" 2>&1 \
    | tee "$OUT/suite.log" | cut -c1-300
python3 benchmarks/bench_gpu.py table "$OUT/cases.jsonl" > "$OUT/table.md"
cat "$OUT/table.md"
nvidia-smi --query-gpu=name,clocks.sm,temperature.gpu --format=csv >> "$OUT/env.txt"
echo "all done at $(($(date +%s) - t0)) s"
