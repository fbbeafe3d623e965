#!/usr/bin/env bash
# paper_bonded at twice the time step, second pairing (issue 20; criteria in
# benchmarks/results/bonded_time_step.md, "Second pairing"): per fresh seed, two processes side
# by side, one core each: (a) the gas compressed to A at the scene's dt_safety 0.15, then the
# branches A->B and A->C->B' of base, null101 and dt2 from that A in one pool of two processes
# (benchmarks/paired_paths.py --pool); (b) the same gas compressed to A at dt_safety 0.30 only
# (--branches none), to pair A itself. Run from a frozen clone:
#   OUT=/work/runs/pbs15 PY=/work/main/.venv/bin/python bash benchmarks/bonded_time_step_overlaps.sh [SEED...]
set -u
here=$(cd "$(dirname "$0")" && pwd)
: "${OUT:?}" "${PY:?}"
mkdir -p "$OUT"
variants=(base= null101=protocol.servo_check_steps=101 dt2=integration.dt_safety=0.30)
variant_args=()
for v in "${variants[@]}"; do variant_args+=(--variant "$v"); done
seeds=("$@")
[ ${#seeds[@]} -eq 0 ] && seeds=(6 7 8)
for seed in "${seeds[@]}"; do
  [ -f "$OUT/seed$seed.done" ] && continue
  start=$(date +%s)
  PYTHONPATH="$here/.." "$PY" "$here/paired_paths.py" --scene paper_bonded --seed "$seed" \
    --set integration.dt_safety=0.30 --variant base= --branches none \
    --out "$OUT/a_dt2_seed$seed.json" > "$OUT/a_dt2_seed$seed.log" 2>&1 &
  side=$!
  PYTHONPATH="$here/.." "$PY" "$here/paired_paths.py" --scene paper_bonded --seed "$seed" \
    --branches isotropic,k0 --pool --workers 2 --out "$OUT/seed$seed.json" \
    "${variant_args[@]}" > "$OUT/seed$seed.log" 2>&1
  rc=$?
  wait "$side"
  rc_side=$?
  echo "seed $seed rc $rc (A at 0.30: rc $rc_side) wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
  [ $rc -eq 0 ] && [ $rc_side -eq 0 ] && touch "$OUT/seed$seed.done"
done
