#!/bin/bash
# Issue 19: a spread of the rods' bond strengths (cells SS05 and SS10): the shipped `study_demo`
# with [long_range] strength_spread σ = 0.5 or 1.0 (each rod's F_max and k_a times a lognormal
# strength of mean 1, the range kept); the isotropic path alone (gas ageing -> A, A->B on to 200,
# probes at every increment), seeds 11, 2, 12, one worker each. Paired by seed with SP05iso
# (study_clay_pstar.sh): the gas is the same, the strengths are drawn from a stream of their own.
# Criteria and results: benchmarks/results/study_clay_spread.md.
#   bash benchmarks/study_clay_spread.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_spread_cells
#   python benchmarks/local_compressibility.py OUT/SS05_s* OUT/SS10_s* PSTAR_OUT/SP05iso_s* \
#       --elastic --out benchmarks/results/study_clay_spread_local
# (PSTAR_OUT: the output folder of study_clay_pstar.sh, whose SP05iso runs are the pairs)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for cell in SS10 SS05; do
  sigma=$([ $cell = SS10 ] && echo 1.0 || echo 0.5)
  for seed in 11 2 12; do
    run_protocol ${cell}_s$seed study_demo --workers 1 --set scene.seed=$seed \
      "${ISOTROPIC_ONLY[@]}" --set long_range.strength_spread=$sigma
  done
done
# SS10F (added after SS05 and SS10, criteria on the page before its runs): σ = 1.0 with F_max and
# k_a raised by 1/0.6504, the mean over random pairs of rods of the harmonic mean of their
# strengths at σ = 1 (10^6 pairs), so that the mean pair's bond is the shipped one (F_max 300)
# and only the spread differs from SP05iso
for seed in 11 2 12; do
  run_protocol SS10F_s$seed study_demo --workers 1 --set scene.seed=$seed \
    "${ISOTROPIC_ONLY[@]}" --set long_range.strength_spread=1.0 \
    --set long_range.f_max_edge=461.3 --set long_range.f_max_inner=461.3 \
    --set long_range.k_a_edge=922.6 --set long_range.k_a_inner=922.6
done
