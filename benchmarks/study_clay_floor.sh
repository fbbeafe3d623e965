#!/bin/bash
# Issue 19: is the gel's compressibility capped by the cohesionless packing of the same rods?
# The rigid `study_demo` rods (300 rods of 8 discs), isotropic path only (to 200 DEM units, probes
# at every increment of A->B and at A and B), seeds 11, 2, 12, one worker each:
#   NA     the rods as shipped (mu 0.5, rolling resistance) without the attraction: the gas aged as
#          the scene ages it, then compressed directly (a cohesionless packing, the floor);
#   NAlow  the same with mu 0.1 and no rolling resistance (the rolling keys dropped from the
#          scene file): the floor of smoother rods;
#   MU01   the scene's gel (attraction, ageing) with mu 0.1 and no rolling resistance.
# The scene as shipped on the same seeds is SP05iso of benchmarks/study_clay_pstar.sh (the same
# isotropic path, bit for bit, on a clone of any later commit of benchmark files only).
# Hypothesis, criteria and results: benchmarks/results/study_clay_floor.md.
#   bash benchmarks/study_clay_floor.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_floor_cells
#   python benchmarks/local_compressibility.py OUT/MU01_s* PSTAR_OUT/SP05iso_s* \
#     --out benchmarks/results/study_clay_floor_local
# (PSTAR_OUT: the output folder of study_clay_pstar.sh; the cell table holds OUT's cells only)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
NO_ROLLING=$(no_rolling_scene)
for seed in 11 2 12; do
  run_protocol NA_s$seed study_demo --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set long_range.enabled=false
  run_protocol NAlow_s$seed "$NO_ROLLING" --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set long_range.enabled=false --set contact.mu=0.1
  run_protocol MU01_s$seed "$NO_ROLLING" --workers 1 --set scene.seed=$seed "${ISOTROPIC_ONLY[@]}" \
    --set contact.mu=0.1
done
