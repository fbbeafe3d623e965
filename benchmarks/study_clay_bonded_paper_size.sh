#!/bin/bash
# Issue 19, stage 2 of the bonded study clay aged as rigid rods (KBR): cell KB300's material
# (study_clay_bonded_stiffness.sh: bonded rods, k_n 3e5, k_t 6e4, k_r 1.2e5, the `rods` thermostat) at the study's size, the
# `study` scene itself (1520 rods, the SP05 gas, probes at every increment, the isotropic path to
# 200), with its gas aged as rigid rods (aggregation_rod_model = "rigid", ageing_rigid_rods.md), the
# K0 path and unloading, no radial paths (to fit a session), the branches on both cores. Seed 11
# (the rigid `study` replica of the same seed: study_scene_sp05_replicas.md). The criteria, stated
# before the run: benchmarks/results/study_clay_bonded_paper_size.md. Run from a frozen clone:
#   bash benchmarks/study_clay_bonded_paper_size.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_bonded_paper_size_cells
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11; do
  run_protocol KBR1520_s$seed study --workers 2 --set scene.seed=$seed \
    --set particles.rod_model=bonded --set protocol.aggregation_thermostat=rods \
    --set protocol.aggregation_rod_model=rigid --set protocol.aggregation_springs=reset \
    --set contact.k_n=3.0e5 --set contact.k_t=6.0e4 --set contact.rolling_stiffness=1.2e5 \
    --set 'protocol.radial_stress_ratios=""' --set protocol.save_path_states=true \
    --set "probing.states=A, B, C, B'"
done
