#!/bin/bash
# Issue 20: the ageing of the gas at twice the scene's time step
# ([protocol] aggregation_time_step_factor = 2) on `study_demo` (300 rods, the sparser gas since
# 2026-12-03), seeds 11, 2, 12, `--workers 2`, one run at a time, from a frozen clone. The
# factor-1 runs are the scene's replicas (study_demo_sp05_replicas.md). Criteria, stated before
# the runs: benchmarks/results/ageing_time_step.md. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/ageing_time_step_cells
#   usage: bash benchmarks/ageing_time_step.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol AGE2_s$seed study_demo --workers 2 --set scene.seed=$seed \
    --set protocol.aggregation_time_step_factor=2
done
