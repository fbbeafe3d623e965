#!/usr/bin/env bash
# The study's-clay servo lever (issue 20; criteria in benchmarks/results/study_servo.md):
# per seed of `study_demo`, the gas is aged and compressed to A once, then each variant runs the
# branches from A (benchmarks/paired_paths.py). Run from a frozen clone:
#   OUT=/work/runs/study_servo PY=/work/main/.venv/bin/python bash benchmarks/study_servo.sh [SEED...]
# VARIANTS (optional): the variants, space-separated NAME=KEY=VALUE;KEY=VALUE... (default: the
# four of study_servo.md; benchmarks/results/study_servo_time.md sets its own).
set -u
here=$(cd "$(dirname "$0")" && pwd)
: "${OUT:?}" "${PY:?}"
mkdir -p "$OUT"
variants=(${VARIANTS:-base= null101=protocol.servo_check_steps=101
  secant=protocol.servo_stiffness=secant
  'secant_s1=protocol.servo_stiffness=secant;protocol.inertial_number_safety=1.0'})
variant_args=()
for v in "${variants[@]}"; do variant_args+=(--variant "$v"); done
seeds=("$@")
[ ${#seeds[@]} -eq 0 ] && seeds=(11 2 12 13 14)
for seed in "${seeds[@]}"; do
  [ -f "$OUT/seed$seed.done" ] && continue
  start=$(date +%s)
  PYTHONPATH="$here/.." "$PY" "$here/paired_paths.py" --scene study_demo --seed "$seed" \
    --workers 2 --out "$OUT/seed$seed.json" \
    "${variant_args[@]}" > "$OUT/seed$seed.log" 2>&1
  rc=$?
  echo "seed $seed rc $rc wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
  [ $rc -eq 0 ] && touch "$OUT/seed$seed.done"
done
