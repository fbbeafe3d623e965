#!/bin/bash
# Issue 19, stage 2: the `study` scene (cell P8 at 1520 rods with the contact stiffness fitted to
# the study's stiffness level, radial paths included) over seeds, the whole protocol with
# --workers 2. The criteria, stated before the runs: benchmarks/results/study_scene.md.
# Run from a frozen clone of the commit to measure, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_scene
#   python -m bridge calibrate --replicas OUT/study_s11 OUT/study_s2 OUT/study_s12 ...
#   usage: bash benchmarks/study_scene_replicas.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
run() {  # run NAME ARGS...: the study scene, branches on both cores
  local name=$1; shift
  run_protocol "$name" study --workers 2 "$@"
}
for seed in 11 2 12; do
  run study_s$seed --set scene.seed=$seed
done
