#!/bin/bash
# The study's-clay candidate of issue 19 at the study's size: does what 300 rods showed hold at
# 1520 rods? Cell P8: RRn8 of study_clay_agitated.sh (the `default` scene with F_max = 300,
# g_max = 0.5 d, the pilots' slow gas, rolling resistance k_r = 4e4, mu_r = 0.5, a sparse gas at
# area fraction 0.10 aged 1000 time units at rms speed 0.5 by the resampling thermostat, 8 discs
# per rod, linear-response probes at every increment, no radial paths), with 1520 rods instead of
# 300. Nothing else changes, so the two sizes differ only by the size. The branches from A run on
# both cores (--workers 2). Seeds 11, 2, 12 as at 300 rods (different gases: the rods differ).
# Run from a frozen clone of the commit to measure, one run at a time. Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_paper_size
#   usage: bash benchmarks/study_clay_paper_size.sh OUT [PYTHON] [ONLY]
#   ONLY: a bash regular expression; only the runs whose name matches it (e.g. '_s11$')
set -u
OUT=${1:?usage: study_clay_paper_size.sh OUT [PYTHON] [ONLY]}
PY=${2:-python}
ONLY=${3:-}
mkdir -p "$OUT"
cell=(--set particles.initial_speed=0.5 --set protocol.gas_strain_rate=0.002
      --set 'protocol.radial_stress_ratios=""' --set 'probing.dynamic_states=""'
      --set probing.every_n_increments=1
      --set long_range.f_max_edge=300 --set long_range.f_max_inner=300
      --set long_range.k_a_edge=600 --set long_range.k_a_inner=600
      --set contact.rolling_stiffness=4e4 --set contact.rolling_friction=0.5
      --set particles.initial_area_fraction=0.1 --set protocol.aggregation=time
      --set protocol.aggregation_time=1000 --set protocol.aggregation_speed=0.5
      --set particles.n_spheres=8 --set particles.n_rods=1520
      --set output.every=5000 --set output.checkpoint_every=100000)
run() {
  local name=$1; shift
  [ -f "$OUT/$name/summary.json" ] && return
  [[ -n $ONLY && ! $name =~ $ONLY ]] && return
  local start; start=$(date +%s)
  "$PY" -m dem_taichi protocol default --out "$OUT/$name" --workers 2 "${cell[@]}" "$@" \
    > "$OUT/$name.log" 2>&1
  echo "$name rc $? wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
}
for seed in 11 2 12; do
  run P8_s$seed --set scene.seed=$seed
done
# Added after the three seeds above had been summarised (2026-12-02 14:05 UTC): C − B was
# positive on all three (+0.57, +0.21, +0.59) but its 95 % interval over three seeds held 0.
# A fourth seed (13) and, decided at 14:11 UTC before seed 13 had finished, a fifth (14), run
# from the same commit as the three (e9cb718), reported beside them.
for seed in 13 14; do
  run P8_s$seed --set scene.seed=$seed
done
