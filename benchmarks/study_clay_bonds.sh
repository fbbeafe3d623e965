#!/bin/bash
# Issue 19: the strength and the range of the gel's bonds (cells F150 and G1): the shipped
# `study_demo` (F_max 300, range g_max = F_max/k_a = 0.5 d) with F_max 150 at the same range
# (k_a 300), or the range doubled to 1 d at the same F_max (k_a 300), both species alike; the
# isotropic path alone (gas ageing -> A, A->B on to 200, probes at every increment), seeds 11, 2,
# 12, one worker each. Paired by seed with SP05iso (study_clay_pstar.sh). Criteria and results:
# benchmarks/results/study_clay_bonds.md.
#   bash benchmarks/study_clay_bonds.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonds_cells
#   python benchmarks/local_compressibility.py OUT/F150_s* OUT/G1_s* PSTAR_OUT/SP05iso_s* \
#       --elastic --out benchmarks/results/study_clay_bonds_local
# (PSTAR_OUT: the output folder of study_clay_pstar.sh, whose SP05iso runs are the pairs)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol F150_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set long_range.f_max_edge=150 --set long_range.f_max_inner=150 \
    --set long_range.k_a_edge=300 --set long_range.k_a_inner=300
done
for seed in 11 2 12; do
  run_protocol G1_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set long_range.k_a_edge=300 --set long_range.k_a_inner=300
done
# cell G025 (added 2026-12-05 after the two ends of study_clay_spread.md; criteria on
# study_clay_bonds.md before its runs): half the range, g_max 0.25 d, at the same F_max (k_a 1200)
for seed in 11 2 12; do
  run_protocol G025_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set long_range.k_a_edge=1200 --set long_range.k_a_inner=1200
done
