#!/bin/bash
# Issue 19: the study scene's isotropic path past B, to 200 kPa (the upper end of the study's
# window), on the seeds of study_scene_replicas.sh: the stress scale by the stiffness on every
# seed (where E_v/p falls through 125), and λ* and the moduli exponent over the whole 1–200 kPa
# window. Only the isotropic path runs (no K0, no unloading, no radial paths); A and B are those
# of the replicas, bit for bit (the extension starts after B).
# The criteria, stated before the runs: benchmarks/results/study_scene_window.md.
# Run from a frozen clone of the commit to measure, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_scene_window
#   usage: bash benchmarks/study_scene_window.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
run() {  # run NAME ARGS...: the study scene's isotropic path alone, to p = 200
  local name=$1; shift
  run_protocol "$name" study --quiet \
    --set protocol.isotropic_end_stress=200 --set protocol.run_k0=false \
    --set protocol.run_unloading=false --set 'protocol.radial_stress_ratios=""' \
    --set 'probing.states="A, B"' "$@"
}
for seed in 11 2 12; do
  run iso200_s$seed --set scene.seed=$seed
done
