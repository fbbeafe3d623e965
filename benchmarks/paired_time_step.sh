#!/usr/bin/env bash
# A scene's paths from A at a multiple of its time step, paired (issue 20): per seed, the gas
# compressed to A once at the scene's Δt, then the branches of every variant from that A in one
# pool of two processes (benchmarks/paired_paths.py --pool):
#   base     the scene as shipped
#   null101  protocol.servo_check_steps = 101 (the null pair: a change that should not matter)
#   pf2      protocol.path_time_step_factor = $FACTOR (the paths at FACTOR × Δt; A unchanged)
# Run from a frozen clone, outputs outside the repository:
#   OUT=/work/runs/spf SCENE=study PY=/work/main/.venv/bin/python bash benchmarks/paired_time_step.sh 11 2 12
# Optional: BRANCHES (default isotropic,k0), FACTOR (default 2). A seed with OUT/seedN.done is
# skipped (rerun the script to resume after an interruption).
set -u
# stopping the script (kill -TERM its pid) stops its pool's workers too: their command line
# names only multiprocessing.spawn, so `pkill -f paired_paths` alone would leave them running
trap 'trap - TERM; kill 0' INT TERM
here=$(cd "$(dirname "$0")" && pwd)
: "${OUT:?}" "${PY:?}" "${SCENE:?}"
branches=${BRANCHES:-isotropic,k0}
factor=${FACTOR:-2}
mkdir -p "$OUT"
variants=(base= null101=protocol.servo_check_steps=101 "pf2=protocol.path_time_step_factor=$factor")
variant_args=()
for v in "${variants[@]}"; do variant_args+=(--variant "$v"); done
for seed in "$@"; do
  [ -f "$OUT/seed$seed.done" ] && continue
  start=$(date +%s)
  PYTHONPATH="$here/.." "$PY" "$here/paired_paths.py" --scene "$SCENE" --seed "$seed" \
    --branches "$branches" --pool --workers 2 --out "$OUT/seed$seed.json" \
    "${variant_args[@]}" > "$OUT/seed$seed.log" 2>&1 &
  wait $!  # in the background, so that a signal runs the trap at once
  rc=$?
  echo "$SCENE seed $seed rc $rc wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
  [ $rc -eq 0 ] && touch "$OUT/seed$seed.done"
done
