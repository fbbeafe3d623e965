#!/bin/bash
# Issue 19: the cap of the rolling resistance (cell RF01): the shipped `study_demo` with
# [contact] rolling_friction 0.1 instead of 0.5 (the rolling springs' stiffness kept, μ 0.5
# kept); the isotropic path alone, seeds 11, 2, 12, one worker each. Paired by seed with SP05iso
# (study_clay_pstar.sh). Criteria and results: benchmarks/results/study_clay_rolling.md.
#   bash benchmarks/study_clay_rolling.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_rolling_cells
#   python benchmarks/local_compressibility.py OUT/RF01_s* PSTAR_OUT/SP05iso_s* --elastic \
#       --out benchmarks/results/study_clay_rolling_local
#   python benchmarks/compression_ends.py OUT/RF01_s* PSTAR_OUT/SP05iso_s* \
#       --out benchmarks/results/study_clay_rolling_ends
# (PSTAR_OUT: the output folder of study_clay_pstar.sh, whose SP05iso runs are the pairs)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol RF01_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set contact.rolling_friction=0.1
done
# cell MU025KR (added after RF01's results, criteria on the page before its runs): MU025K's
# rods (study_clay_smooth.sh: mu 0.25) with RF01's rolling cap (rolling_friction 0.1), the
# contact springs refitted by the stiffness rule on RF01's measured stiffening (E_v/p at B x1.29
# against SP05iso): MU025K's k_n 4.4e4 / 1.29 = 3.4e4, k_t and k_r in proportion; the whole
# `study_demo` protocol (K0 and unloading included), seeds 11, 2, 12
for seed in 11 2 12; do
  run_protocol MU025KR_s$seed study_demo --workers 1 --set scene.seed=$seed --set contact.mu=0.25 \
    --set contact.k_n=3.4e4 --set contact.k_t=6.8e3 --set contact.rolling_stiffness=1.36e4 \
    --set contact.rolling_friction=0.1
done
