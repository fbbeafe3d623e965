#!/bin/bash
# Issue 19: how long the gas ages before its compression (cells AG500 and AG8000): the shipped
# `study_demo` with protocol.aggregation_time 500 or 8000 time units (shipped: 2000), the
# isotropic path alone (gas ageing -> A, A->B on to 200, probes at every increment), seeds 11, 2,
# 12, one worker each. Paired by seed with SP05iso (the shipped scene's isotropic runs,
# study_clay_pstar.sh). Criteria and results: benchmarks/results/study_clay_ageing.md.
#   bash benchmarks/study_clay_ageing.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_ageing_cells
#   python benchmarks/local_compressibility.py OUT/AG*_s* PSTAR_OUT/SP05iso_s* --elastic \
#       --out benchmarks/results/study_clay_ageing_local
# (PSTAR_OUT: the output folder of study_clay_pstar.sh, whose SP05iso runs are the pairs)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol AG500_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set protocol.aggregation_time=500
done
for seed in 11 2 12; do
  run_protocol AG8000_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set protocol.aggregation_time=8000
done
