# Sourced by the issue-19 run scripts, with their arguments OUT [PYTHON] [ONLY]: sets OUT (the
# output folder, created), PY (default python) and ONLY (a bash regular expression, default
# empty: every run) from them, and defines
# run_protocol NAME SCENE [ARGS...], which runs
#   $PY -m dem_taichi protocol SCENE --out $OUT/NAME ARGS...
# unless NAME has finished ($OUT/NAME/summary.json exists) or does not match $ONLY (when set);
# its output goes to $OUT/NAME.log, and "NAME rc R wall S s" is appended to $OUT/summary.txt.
OUT=${1:?usage: $(basename "$0") OUT [PYTHON] [ONLY]}
PY=${2:-python}
ONLY=${3:-}
mkdir -p "$OUT"
run_protocol() {
  local name=$1 scene=$2; shift 2
  [ -f "$OUT/$name/summary.json" ] && return
  [[ -n $ONLY && ! $name =~ $ONLY ]] && return
  local start; start=$(date +%s)
  "$PY" -m dem_taichi protocol "$scene" --out "$OUT/$name" "$@" > "$OUT/$name.log" 2>&1
  echo "$name rc $? wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
}
