#!/bin/bash
# Issue 19, stage 2 with bonded rods: cell KB300's material (study_clay_bonded_stiffness.sh:
# bonded rods, k_n 3e5, k_t 6e4, k_r 1.2e5, the `rods` thermostat), its gas aged as bonded rods
# (not as a rigid twin: KBR is another material, ageing_rigid_rods.md), at the study's size: the
# `study` scene itself (1520 rods, the SP05 gas, probes at every increment, the isotropic path to
# 200, the K0 path and unloading, the three radial paths), `--workers 2`, seeds 11, 2, 12 in turn.
# About 3-4 h per seed on 2 cores, so a run spans sessions: each session runs this script again
# (from a frozen clone of the same commit); a stopped run goes on from its last save (inside the
# ageing about every 10 min, at the ageing's end, at A, each finished branch). Criteria, stated
# before the runs: benchmarks/results/study_clay_bonded_stage2.md.
#   bash benchmarks/study_clay_bonded_stage2.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonded_stage2_cells
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol KB1520_s$seed study --workers 2 --set scene.seed=$seed \
    --set particles.rod_model=bonded --set protocol.aggregation_thermostat=rods \
    --set contact.k_n=3.0e5 --set contact.k_t=6.0e4 --set contact.rolling_stiffness=1.2e5 \
    --set protocol.save_path_states=true
done
