#!/bin/bash
# Issue 19, what users see first: the `study_demo` scene (the `study` scene's material at 300
# rods, what `make demo` runs) over the three seeds of the study scene's replicas, the whole
# protocol with --workers 2, as the demo runs it. The criteria, stated before the runs:
# benchmarks/results/study_demo.md. Run from a frozen clone, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_demo_replicas
#   usage: bash benchmarks/study_demo_replicas.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol study_demo_s$seed study_demo --workers 2 --set scene.seed=$seed
done
