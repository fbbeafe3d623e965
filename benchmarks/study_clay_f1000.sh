#!/bin/bash
# Issue 19, stage 1's F_max = 1000 cell: the `study_demo` material with an attraction 10/3 times
# stronger (F_max = 1000, the range kept at g_max = 0.5 d: k_a = 2000) and a contact stiffness
# raised as the issue's matrix asks (k_n = 3e5; k_t, rolling stiffness in the same ratios), the A
# criterion at the same reduced pressure P* = p d / F_max as the study's (0.5/300), the isotropic
# path on to 3 F_max/d = 3000; three seeds, `--workers 2`. The criteria, stated before the runs:
# benchmarks/results/study_clay_f1000.md. Run from a frozen clone, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_f1000_cells
#   usage: bash benchmarks/study_clay_f1000.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol KF1000_s$seed study_demo --workers 2 --set scene.seed=$seed \
    --set long_range.f_max_edge=1000 --set long_range.f_max_inner=1000 \
    --set long_range.k_a_edge=2000 --set long_range.k_a_inner=2000 \
    --set contact.k_n=3.0e5 --set contact.k_t=6.0e4 --set contact.rolling_stiffness=1.2e5 \
    --set protocol.pressure_tolerance_reduced=0.0016666666666666668 \
    --set protocol.isotropic_end_stress=3000
done
