#!/bin/bash
# Issue 19, the bonded study's clay: its overlaps below the bar at the same stiffness level (cell
# KB300S, a pilot on seed 11 first). KB300's material with the contacts twice as stiff (k_n 6e5,
# k_t 1.2e5, k_r 2.4e5: the ratios 0.2 and 0.4 kept) and the bonds' absolute stiffness kept (their
# ratios to k_n halved: normal 0.5, shear 0.1, bending 0.15), so that more of the rods' compliance
# is in the bonds and less in the contacts. The isotropic path only, every relaxed increment
# saved. Criteria, stated before the run: benchmarks/results/study_clay_bonded_overlap.md. Run
# from a frozen clone, outputs outside the repository:
#   bash benchmarks/study_clay_bonded_overlap.sh OUT [PYTHON] [ONLY]    (the pilot: ONLY='s11$')
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonded_overlap_cells
# After the pilot met its two hints (the page), the other seeds and each seed's K0 path and
# unloading from its saved A (benchmarks/paired_paths.py --from-run, OUT/KB300S_s<seed>_k0.json)
# follow, as for KB300.
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
bonded_cell KB300S --set contact.k_n=6.0e5 --set contact.k_t=1.2e5 \
  --set contact.rolling_stiffness=2.4e5 --set bonds.normal=0.5 --set bonds.shear=0.1 \
  --set bonds.bending=0.15
for seed in 11 2 12; do
  k0_from_run KB300S_s$seed
done
