#!/bin/bash
# Issue 19: attraction only between the rods bonded at state A (cells BA and MKBA): the shipped
# `study_demo` with [long_range] attraction_pairs = "bonded_at_A" (from A on, rods that meet do
# not bond; repulsion unchanged; the gas, its ageing and A unchanged). BA: the isotropic path alone
# (gas ageing -> A, A->B on to 200, probes at every increment, path states saved), seeds 11, 2,
# 12, one worker each, paired by seed with SP05iso (study_clay_pstar.sh), whose A it shares bit
# for bit.
# Then the K0 path and unloading from each run's A (paired_paths.py --from-run: OUT/<run>_k0.json),
# and, with PAIRS=DIR set (a folder of links to study_clay_pstar.sh's SP05iso_s<seed> runs), the
# same from SP05iso's A (DIR/SP05iso_s<seed>_k0.json), for the K0 findings paired from one A.
# Criteria and results: benchmarks/results/study_clay_partners.md.
#   [PAIRS=DIR] bash benchmarks/study_clay_partners.sh OUT [PYTHON] [ONLY]
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_partners_cells
#   python benchmarks/study_clay_pilots.py PAIRS --out benchmarks/results/study_clay_partners_pairs
#   python benchmarks/runs_paired.py benchmarks/results/study_clay_pstar_cells_runs.csv \
#       benchmarks/results/study_clay_partners_cells_runs.csv --before-cell SP05iso --after-cell BA
set -u
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
for seed in 11 2 12; do
  run_protocol BA_s$seed study_demo --workers 1 --set scene.seed=$seed \
    "${ISOTROPIC_ONLY[@]}" --set long_range.attraction_pairs=bonded_at_A \
    --set protocol.save_path_states=true
done
# cell MKBA (added after BA's results, criteria on the page before its runs): MU025K
# (study_clay_smooth.sh: mu 0.25, k_n refitted to 4.4e4) with the option, the whole protocol,
# paired with MU025K's runs from the same A
for seed in 11 2 12; do
  run_protocol MKBA_s$seed study_demo --workers 1 --set scene.seed=$seed --set contact.mu=0.25 \
    --set contact.k_n=4.4e4 --set contact.k_t=8.8e3 --set contact.rolling_stiffness=1.76e4 \
    --set long_range.attraction_pairs=bonded_at_A
done
for seed in 11 2 12; do
  k0_from_run BA_s$seed
  if [ -n "${PAIRS:-}" ]; then OUT=$PAIRS k0_from_run SP05iso_s$seed; fi
done
