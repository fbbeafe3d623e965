#!/bin/bash
# Issue 19, stage 2: the `study` scene (cell P8 at 1520 rods with the contact stiffness fitted to
# the study's stiffness level, radial paths included) over seeds, the whole protocol with
# --workers 2. The criteria, stated before the runs: benchmarks/results/study_scene.md.
# Run from a frozen clone of the commit to measure, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_scene
#   python -m bridge calibrate --replicas OUT/study_s11 OUT/study_s2 OUT/study_s12 ...
#   usage: bash benchmarks/study_scene_replicas.sh OUT [PYTHON] [ONLY]
set -u
OUT=${1:?usage: study_scene_replicas.sh OUT [PYTHON] [ONLY]}
PY=${2:-python}
ONLY=${3:-}
mkdir -p "$OUT"
run() {
  local name=$1; shift
  [ -f "$OUT/$name/summary.json" ] && return
  [[ -n $ONLY && ! $name =~ $ONLY ]] && return
  local start; start=$(date +%s)
  "$PY" -m dem_taichi protocol study --out "$OUT/$name" --workers 2 "$@" > "$OUT/$name.log" 2>&1
  echo "$name rc $? wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
}
for seed in 11 2 12; do
  run study_s$seed --set scene.seed=$seed
done
