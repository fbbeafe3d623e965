#!/bin/bash
# Issue 20: the bonded study cell KB300 (study_clay_bonded_stiffness.sh) with its gas aged as rigid
# rods ([protocol] aggregation_rod_model = "rigid": cell KBR300), seeds 11, 2, 12, the isotropic
# path, then the K0 path and unloading from each run's saved A. Paired with KB300's runs on the
# same seeds (the same gas). The criteria, stated before the runs:
# benchmarks/results/ageing_rigid_rods.md. Run from a frozen clone; the three seeds may run at
# once (ONLY = 's11$', 's2$', 's12$' in three processes), as KB300's did. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/ageing_rigid_rods_cells
#   usage: bash benchmarks/ageing_rigid_rods.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
# the springs reset at the hand-over, as in these runs (the default since is "kept")
bonded_cell KBR300 --set protocol.aggregation_rod_model=rigid \
  --set protocol.aggregation_springs=reset
for seed in 11 2 12; do
  k0_from_run KBR300_s$seed
done
