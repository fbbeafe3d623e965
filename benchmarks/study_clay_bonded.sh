#!/bin/bash
# Issue 19, rigid against bonded rods for the study's clay: the `study_demo` material (cell K70 =
# P8 at 300 rods with k_n = 7e4) with bonded rods (the bonds of paper_bonded: k_bn = k_n,
# k_bt = 0.2 k_n, bending 0.3 k_n d^2) and the ageing thermostat on the rods' rigid-body motion
# ("rods": each rod's centre of mass at rms speed 0.5, as the rigid rods'), no radial paths (as
# K70). The criteria, stated before the runs: benchmarks/results/study_clay_bonded.md.
# Run from a frozen clone, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonded
#   usage: bash benchmarks/study_clay_bonded.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol KB70_s$seed study_demo --workers 2 --set scene.seed=$seed \
    --set particles.rod_model=bonded --set protocol.aggregation_thermostat=rods \
    --set 'protocol.radial_stress_ratios=""' --set "probing.states=A, B, C, B'"
done
