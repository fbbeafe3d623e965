#!/bin/bash
# Issue 19, stage 1: two more ways to a looser gel at the study's compressibility, on the
# `study_demo` material (300 rods of 8 discs, F_max 300, g_max 0.5 d, k_n 7e4, aged 1000 time
# units at rms speed 0.5, the isotropic path on to 200 kPa), each changing one thing:
#   SP05  a sparser gas: initial area fraction 0.05 instead of 0.10, aged 2000 time units (twice
#         as long, for about as many encounters per rod as at 0.10)
#   D12   longer rods: 12 discs per rod instead of 8 (5 -> 8 -> 10 discs gave lambda* 0.120 ->
#         0.133 -> 0.147 in study_clay_agitated)
# Three seeds each, `--workers 2`, no radial paths (as study_demo). The criteria, stated before
# the runs: benchmarks/results/study_clay_looser.md. Run from a frozen clone, one run at a time:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_looser_cells
#   usage: bash benchmarks/study_clay_looser.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol SP05_s$seed study_demo --workers 2 --set scene.seed=$seed \
    --set particles.initial_area_fraction=0.05 --set protocol.aggregation_time=2000
done
for seed in 11 2 12; do
  run_protocol D12_s$seed study_demo --workers 2 --set scene.seed=$seed \
    --set particles.n_spheres=12 \
    --set particles.initial_area_fraction=0.1 --set protocol.aggregation_time=1000
done
