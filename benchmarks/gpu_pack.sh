#!/usr/bin/env bash
# Builds .gpu/, what benchmarks/gpu_device.sh needs on the lent device machine (Python 3.12, no
# network; see its header): Taichi 1.7.4 for CPython 3.12 unpacked, less its C API library and
# examples (not used from Python), xz-compressed (56 MiB wheel -> 22 MiB, under the 64 MiB a call
# may carry); the wheels that machine lacks; the jammed 1520-rod packing the cases tile.
# Run here (this machine has the network and the project's .venv):
#   bash benchmarks/gpu_pack.sh            # then: run(command="PLAN=rerun bash benchmarks/gpu_device.sh", carry=[".gpu"])
set -eu
cd "$(dirname "$0")/.."
grep -qx '/.gpu/' .git/info/exclude 2>/dev/null || echo '/.gpu/' >> .git/info/exclude
mkdir -p .gpu
tmp=$(mktemp -d)
platforms=(--platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64
           --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64)
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp "${platforms[@]}" -d "$tmp" taichi==1.7.4
python3 -m pip install -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp "${platforms[@]}" --target "$tmp/site" "$tmp"/taichi-1.7.4-*.whl
rm -rf "$tmp/site/taichi/_lib/c_api" "$tmp/site/taichi/examples" "$tmp/site/include" \
    "$tmp/site/share" "$tmp/site/bin"
find "$tmp/site" -name __pycache__ -prune -exec rm -rf {} +
tar -cJf .gpu/taichi312.tar.xz -C "$tmp/site" .
# netCDF4 and cftime (abi3 wheels), dill (Taichi), pint and its needs: not on that machine
python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --implementation cp "${platforms[@]}" -d .gpu \
    netCDF4 cftime dill pint flexcache flexparser platformdirs
[ -f .gpu/gpu_state.npz ] || .venv/bin/python benchmarks/bench_gpu.py prepare --out .gpu/gpu_state.npz
rm -rf "$tmp"
du -sh .gpu
