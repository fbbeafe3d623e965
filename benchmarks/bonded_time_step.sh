#!/usr/bin/env bash
# paper_bonded's paths from A at twice the time step (issue 20; criteria in
# benchmarks/results/bonded_time_step.md): per seed, state A once (seed 3 from the 29.2-min run's
# folder, RUN3), then the variants' branches A->B and A->C->B' in one pool of two processes
# (benchmarks/paired_paths.py --pool). Run from a frozen clone:
#   OUT=/work/runs/pbs14 PY=/work/main/.venv/bin/python RUN3=/work/runs/pb13/paper_bonded_radial_s3 \
#     bash benchmarks/bonded_time_step.sh [SEED...]
set -u
here=$(cd "$(dirname "$0")" && pwd)
: "${OUT:?}" "${PY:?}"
mkdir -p "$OUT"
variants=(base= null101=protocol.servo_check_steps=101 dt2=integration.dt_safety=0.30)
variant_args=()
for v in "${variants[@]}"; do variant_args+=(--variant "$v"); done
seeds=("$@")
[ ${#seeds[@]} -eq 0 ] && seeds=(3 4 5)
for seed in "${seeds[@]}"; do
  [ -f "$OUT/seed$seed.done" ] && continue
  if [ "$seed" = 3 ] && [ -n "${RUN3:-}" ]; then
    source_args=(--from-run "$RUN3")
  else
    source_args=(--scene paper_bonded --seed "$seed")
  fi
  start=$(date +%s)
  PYTHONPATH="$here/.." "$PY" "$here/paired_paths.py" "${source_args[@]}" \
    --branches isotropic,k0 --pool --workers 2 --out "$OUT/seed$seed.json" \
    "${variant_args[@]}" > "$OUT/seed$seed.log" 2>&1
  rc=$?
  echo "seed $seed rc $rc wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
  [ $rc -eq 0 ] && touch "$OUT/seed$seed.done"
done
