#!/usr/bin/env bash
# The `fast` preset on the `study` scene's branches from A (issue 20; criteria in
# benchmarks/results/study_fast_preset.md): per finished `study` replica, its state A is taken
# (benchmarks/paired_paths.py --from-run) and the branches run once per variant. Run from a
# frozen clone:
#   OUT=/work/runs/fast PY=/work/main/.venv/bin/python bash benchmarks/study_fast_preset.sh RUN...
# VARIANTS (optional): space-separated NAME=KEY=VALUE;KEY=VALUE... (default: fast, then base).
set -u
here=$(cd "$(dirname "$0")" && pwd)
: "${OUT:?}" "${PY:?}"
mkdir -p "$OUT"
fast='integration.dt_safety=0.25;control.inertial_number_max=3e-3;protocol.relax_unbalanced_force=1e-3;protocol.stress_tolerance=3e-3;protocol.servo_stiffness=secant;probing.relax_unbalanced_force=1e-6'
variants=(${VARIANTS:-"fast=$fast" base=})
variant_args=()
for v in "${variants[@]}"; do variant_args+=(--variant "$v"); done
for run in "$@"; do
  name=$(basename "$run")
  [ -f "$OUT/$name.done" ] && continue
  start=$(date +%s)
  PYTHONPATH="$here/.." "$PY" "$here/paired_paths.py" --from-run "$run" --workers 2 \
    --out "$OUT/$name.json" "${variant_args[@]}" > "$OUT/$name.log" 2>&1
  rc=$?
  echo "$name rc $rc wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
  [ $rc -eq 0 ] && touch "$OUT/$name.done"
done
