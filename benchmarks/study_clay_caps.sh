#!/bin/bash
# Issue 19: contacts whose caps do not grow with the attraction (cell NC): the shipped
# `study_demo` with [contact] cap_force = "net" (the sliding cap μ|f| and the rolling cap
# μ_r (d/2)|f| from the contact force less the pair's attraction, from the gas on: a departure
# from the study's MercuryDPM laws). The isotropic path alone (gas ageing -> A, A->B on to 200,
# probes at every increment, path states saved), seeds 11, 2, 12, one worker each, beside SP05iso
# (study_clay_pstar.sh: the same gases under the study's caps).
# Criteria and results: benchmarks/results/study_clay_caps.md.
#   bash benchmarks/study_clay_caps.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_caps_cells
# (NC first, then NCA; run with ONLY = NC_ or NCA_ to run one cell)
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol NC_s$seed study_demo --workers 1 --set scene.seed=$seed \
    "${ISOTROPIC_ONLY[@]}" --set contact.cap_force=net --set protocol.save_path_states=true
done
# cell NCA (added after NC's results, criteria on the page before its runs): the study's caps up
# to A, the net caps from A on (cap_force = "net_after_A"), paired with SP05iso from the same A
for seed in 11 2 12; do
  run_protocol NCA_s$seed study_demo --workers 1 --set scene.seed=$seed \
    "${ISOTROPIC_ONLY[@]}" --set contact.cap_force=net_after_A --set protocol.save_path_states=true
done
