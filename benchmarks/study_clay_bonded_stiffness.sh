#!/bin/bash
# Issue 19, the bonded study's clay: its stiffness fit at 300 rods (cell KB300). The `study_demo`
# material (the SP05 gas: area fraction 0.05, aged 2000) with bonded rods (the bonds of
# paper_bonded, relative to k_n: k_bn = k_n, k_bt = 0.2 k_n, bending 0.3 k_n d^2), the ageing
# thermostat on the rods' rigid-body motion, and the contact stiffness raised from 7e4 to 3.0e5
# (k_t = 0.2 k_n and k_r = 0.4 k_n kept): KB70's E_v/p at B (29 +- 8) scaled to 125. The isotropic
# path only (A -> B -> 200), every relaxed increment saved (the bonded rods' overlaps are computed
# from the saved states). The criteria, stated before the runs:
# benchmarks/results/study_clay_bonded_stiffness.md. Then the K0 path and unloading of each
# finished run from its saved A (benchmarks/paired_paths.py --from-run, OUT/KB300_s<seed>_k0.json;
# the page's K0 runs were started by a watcher with the same command). Run from a frozen clone;
# the three seeds may run at once (ONLY = 's11$', 's2$', 's12$' in three processes). Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonded_stiffness_cells
#   usage: bash benchmarks/study_clay_bonded_stiffness.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
bonded_cell KB300  # (study_clay_run.sh)
for seed in 11 2 12; do
  k0_from_run KB300_s$seed
done
# KB300F600 (stated after KB300's results, before its own runs; the page's last section): the same
# cell with the attraction doubled at the same range (F_max 600, k_a 1200: g_max 0.5 d), so that
# F_max/(k_n d) goes halfway back to the rigid scene's 4.3e-3. The isotropic path only.
bonded_cell KB300F600 --set long_range.f_max_edge=600 --set long_range.f_max_inner=600 \
  --set long_range.k_a_edge=1200 --set long_range.k_a_inner=1200
