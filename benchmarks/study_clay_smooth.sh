#!/bin/bash
# Issue 19: the `study_demo` gel on smoother rods with its stiffness level fitted (cell MU01K):
# mu 0.1 and no rolling resistance (cell MU01 of study_clay_floor.sh, the rolling keys dropped from
# the scene file), the contact springs scaled by 125 over MU01's mean E_v/p at B (the rule of
# study_clay_stiffness.md: moduli proportional to k_n at a fixed structure; k_t/k_n 0.2 kept),
# the whole `study_demo` protocol (gas ageing -> A, A->B on to 200, A->C K0, C->B' unloading,
# probes at every increment), seeds 11, 2, 12, one worker each (the machine's cores are shared).
# Criteria and results: benchmarks/results/study_clay_smooth.md.
#   bash benchmarks/study_clay_smooth.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_smooth_cells
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
NO_ROLLING=$(no_rolling_scene)
for seed in 11 2 12; do
  run_protocol MU01K_s$seed "$NO_ROLLING" --workers 1 --set scene.seed=$seed \
    --set contact.mu=0.1 --set contact.k_n=3.7e4 --set contact.k_t=7.4e3
done
# cell MU025 (added after MU01K's results): the shipped scene with mu 0.25, everything else kept
for seed in 11 2 12; do
  run_protocol MU025_s$seed study_demo --workers 1 --set scene.seed=$seed --set contact.mu=0.25
done
# cell MU025K (added after MU025's results): MU025 with its stiffness refitted, k_n = 7e4 x 125/199
for seed in 11 2 12; do
  run_protocol MU025K_s$seed study_demo --workers 1 --set scene.seed=$seed --set contact.mu=0.25 \
    --set contact.k_n=4.4e4 --set contact.k_t=8.8e3 --set contact.rolling_stiffness=1.76e4
done
