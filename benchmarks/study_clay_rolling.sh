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
