# Sourced by the issue-19 run scripts, with their arguments OUT [PYTHON] [ONLY]: sets OUT (the
# output folder, created), PY (default python) and ONLY (a bash regular expression, default
# empty: every run) from them, and defines
# run_protocol NAME SCENE [ARGS...], which runs
#   $PY -m dem_taichi protocol SCENE --out $OUT/NAME ARGS...
# unless NAME has finished ($OUT/NAME/summary.json exists) or does not match $ONLY (when set);
# its output goes to $OUT/NAME.log, and "NAME rc R wall S s" is appended to $OUT/summary.txt.
# The scripts that run the `study` or `study_demo` scenes reproduce their pages' tables from a
# clone of the commit the page names. Since 2026-12-03 both scenes age a gas of area fraction 0.05
# for 2000 time units (cell SP05, study_clay_looser.md); runs of the earlier material (0.10, 1000)
# on a later clone need `--set particles.initial_area_fraction=0.1 --set
# protocol.aggregation_time=1000` (study_clay_looser.sh's D12 sets them).
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
