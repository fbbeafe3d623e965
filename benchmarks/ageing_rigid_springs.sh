#!/bin/bash
# Issue 20: the bonded study cell aged as rigid rods with the contacts' springs carried over at the
# hand-over ([protocol] aggregation_springs = "kept": cell KBRK300), against KBR300 (the springs
# reset, ageing_rigid_rods.sh) and KB300 (bonded ageing), seeds 11, 2, 12: the isotropic path,
# then the K0 path and unloading from each run's saved A. The criteria, stated before the runs:
# benchmarks/results/ageing_rigid_springs.md. Run from a frozen clone; the three seeds may run at
# once (ONLY = 's11$', 's2$', 's12$' in three processes), as KB300's and KBR300's did. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/ageing_rigid_springs_cells
#   usage: bash benchmarks/ageing_rigid_springs.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
bonded_cell KBRK300 --set protocol.aggregation_rod_model=rigid \
  --set protocol.aggregation_springs=kept
for seed in 11 2 12; do
  k0_from_run KBRK300_s$seed
done
