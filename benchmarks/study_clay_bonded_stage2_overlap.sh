#!/bin/bash
# Issue 19, the overlap bar at the study's size: one replica (seed 11) of KB300S's keys (the
# contacts twice as stiff as KB1520's, k_n 6e5, k_t 1.2e5, k_r 2.4e5; the bonds' absolute
# stiffness kept: normal 0.5, shear 0.1, bending 0.15 of k_n) in the `study` scene, otherwise
# run as KB1520 (study_clay_bonded_stage2.sh: the gas aged as bonded rods, `--workers 2`, path
# states saved). Runs after KB1520's three seeds; about 4-5 h on 2 cores, so it spans sessions:
# each session runs this again from a frozen clone, and a stopped run goes on from its saves.
# Criteria, stated before the run: benchmarks/results/study_clay_bonded_stage2.md, "Seeds 2 and
# 12, and the overlap bar".
#   bash benchmarks/study_clay_bonded_stage2_overlap.sh OUT [PYTHON]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonded_stage2_overlap_cells
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
run_protocol KS1520_s11 study --workers 2 --set scene.seed=11 \
  --set particles.rod_model=bonded --set protocol.aggregation_thermostat=rods \
  --set contact.k_n=6.0e5 --set contact.k_t=1.2e5 --set contact.rolling_stiffness=2.4e5 \
  --set bonds.normal=0.5 --set bonds.shear=0.1 --set bonds.bending=0.15 \
  --set protocol.save_path_states=true
