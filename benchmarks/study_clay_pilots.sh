#!/bin/bash
# The study's-clay pilots of issue 19 (servo check on loose aggregated structures), 3 seeds per
# cell: the default protocol without radial paths (A->B, A->C, C->B'), linear-response probes at
# every increment, no dynamic sweep. Run from a frozen clone of the commit to measure; one run
# at a time (2 cores). Then: python benchmarks/study_clay_pilots.py OUT
#   usage: bash benchmarks/study_clay_pilots.sh OUT [PYTHON]
set -u
OUT=${1:?usage: study_clay_pilots.sh OUT [PYTHON]}
PY=${2:-python}
mkdir -p "$OUT"
common=(--set particles.initial_speed=0.5 --set protocol.gas_strain_rate=0.002
        --set 'protocol.radial_stress_ratios=""' --set 'probing.dynamic_states=""'
        --set probing.every_n_increments=1)
declare -A cfg
cfg[F100]="long_range.f_max_edge=100 long_range.f_max_inner=100 long_range.k_a_edge=200 long_range.k_a_inner=200"
cfg[F300g1]="long_range.f_max_edge=300 long_range.f_max_inner=300 long_range.k_a_edge=300 long_range.k_a_inner=300"
cfg[F300mu02]="long_range.f_max_edge=300 long_range.f_max_inner=300 long_range.k_a_edge=600 long_range.k_a_inner=600 contact.mu=0.2"
cfg[F300]="long_range.f_max_edge=300 long_range.f_max_inner=300 long_range.k_a_edge=600 long_range.k_a_inner=600"
for name in F300 F300mu02 F100 F300g1; do
  sets=()
  for kv in ${cfg[$name]}; do sets+=(--set "$kv"); done
  for seed in 11 2 12; do
    run="$OUT/${name}_s${seed}"
    [ -f "$run/summary.json" ] && continue
    start=$(date +%s)
    "$PY" -m dem_taichi protocol default --out "$run" --quiet "${sets[@]}" "${common[@]}" \
      --set scene.seed=$seed > "$run.log" 2>&1
    echo "$name seed $seed rc $? wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
  done
done
