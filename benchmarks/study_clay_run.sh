# Sourced by the issue-19 run scripts. run_protocol NAME SCENE [ARGS...] runs
#   $PY -m dem_taichi protocol SCENE --out $OUT/NAME ARGS...
# unless NAME has finished ($OUT/NAME/summary.json exists) or does not match the bash regular
# expression $ONLY (when set); its output goes to $OUT/NAME.log, and "NAME rc R wall S s" is
# appended to $OUT/summary.txt. Needs OUT, PY and ONLY.
run_protocol() {
  local name=$1 scene=$2; shift 2
  [ -f "$OUT/$name/summary.json" ] && return
  [[ -n $ONLY && ! $name =~ $ONLY ]] && return
  local start; start=$(date +%s)
  "$PY" -m dem_taichi protocol "$scene" --out "$OUT/$name" "$@" > "$OUT/$name.log" 2>&1
  echo "$name rc $? wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
}
