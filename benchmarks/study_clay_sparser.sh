#!/bin/bash
# Issue 19, stage 1: a still sparser gas on the study's clay. SP025 = `study_demo` (300 rods, the
# scene as shipped since 2026-12-03: the SP05 gas, area fraction 0.05 aged 2000 time units) with
# the gas at area fraction 0.025 aged 4000 time units (twice as long again, for about as many
# encounters per rod). SP05 against the 0.10 gas raised lambda* on every seed (+0.016, +0.033,
# +0.047); this asks whether the trend goes on. Three seeds, `--workers 2`, no radial paths (as
# study_demo). The criteria, stated before the runs: benchmarks/results/study_clay_sparser.md.
# Run from a frozen clone (the seeds may run at once, ONLY = 's11$', 's2$', 's12$'). Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_sparser_cells
#   usage: bash benchmarks/study_clay_sparser.sh OUT [PYTHON] [ONLY]
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol SP025_s$seed study_demo --workers 2 --set scene.seed=$seed \
    --set particles.initial_area_fraction=0.025 --set protocol.aggregation_time=4000
done
