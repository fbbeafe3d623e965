#!/bin/bash
# Issue 19, the stiffness level: does E_v/p of cell P8 scale with the contact stiffness at a fixed
# preparation, so that the study's E_v/p = 125 at 100 kPa can be met at 1 kPa per DEM unit by
# fitting k_n (Pi_F = F_max/(k_n d)) instead of moving the stress scale out of the collapse
# window? Cells, 300 rods (study_clay_cell_p8.sh), the whole protocol without radial paths:
#   K70   P8 with k_n = 7e4, k_t = 1.4e4, k_r = 2.8e4 (k_t/k_n and k_r/k_n kept; 1e5 x 125/177,
#         177 = E_v/p at B of P8 at 1520 rods, five seeds)
# against RRn8 of study_clay_agitated.sh (the same cell at k_n = 1e5, the same seeds).
# The criteria, stated before the runs: benchmarks/results/study_clay_stiffness.md.
# Run from a frozen clone of the commit to measure, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_stiffness
#   usage: bash benchmarks/study_clay_stiffness.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_cell_p8.sh"
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
run() {  # run NAME ARGS...: cell P8 on the default scene
  local name=$1; shift
  run_protocol "$name" default --quiet "${p8_cell[@]}" "$@"
}
for seed in 11 2 12; do
  run K70_s$seed --set contact.k_n=7e4 --set contact.k_t=1.4e4 \
    --set contact.rolling_stiffness=2.8e4 --set scene.seed=$seed
done
