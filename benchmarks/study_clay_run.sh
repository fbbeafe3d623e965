# Sourced by the issue-19 run scripts, with their arguments OUT [PYTHON] [ONLY]: sets OUT (the
# output folder, created), PY (default python) and ONLY (a bash regular expression, default
# empty: every run) from them, and defines
# run_protocol NAME SCENE [ARGS...], which runs
#   $PY -m dem_taichi protocol SCENE --out $OUT/NAME ARGS...
# unless NAME has finished ($OUT/NAME/summary.json exists) or does not match $ONLY (when set);
# its output goes to $OUT/NAME.log, and "NAME rc R wall S s" is appended to $OUT/summary.txt;
# bonded_cell CELL [ARGS...], the isotropic runs CELL_s11, CELL_s2, CELL_s12 of the bonded study
# cell KB300 (study_clay_bonded_stiffness.sh) with extra ARGS; k0_from_run NAME, the K0 path
# and unloading of the finished run NAME from its saved A (paired_paths.py --from-run, into
# $OUT/NAME_k0.json), unless done; ISOTROPIC_ONLY, the overrides of a run of the isotropic path
# alone (probes at A and B besides every increment); and no_rolling_scene, which writes the
# built-in `study_demo` without its rolling keys (no rolling resistance: --set cannot remove a
# key) to $OUT/study_demo_no_rolling.toml and prints that path.
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
  local start resume=(); start=$(date +%s)
  # a run stopped before its end (a session's end) goes on from its saves (resume/: inside the
  # ageing, at A, the finished branches), its log appended
  [ -f "$OUT/$name/run.json" ] && resume=(--resume)
  "$PY" -m dem_taichi protocol "$scene" --out "$OUT/$name" "${resume[@]}" "$@" \
    >> "$OUT/$name.log" 2>&1
  echo "$name rc $? wall $(( $(date +%s) - start )) s${resume:+ (resumed)}" >> "$OUT/summary.txt"
}
ISOTROPIC_ONLY=(--set protocol.run_k0=false --set protocol.run_unloading=false
  --set 'probing.states=A, B')
no_rolling_scene() {
  local scene=$OUT/study_demo_no_rolling.toml
  grep -v '^rolling_' "$(dirname "${BASH_SOURCE[0]}")/../dem_taichi/scenes/study_demo.toml" > "$scene"
  echo "$scene"
}
bonded_cell() {
  local cell=$1 seed; shift
  for seed in 11 2 12; do
    run_protocol ${cell}_s$seed study_demo --workers 1 --set scene.seed=$seed \
      --set particles.rod_model=bonded --set protocol.aggregation_thermostat=rods \
      --set contact.k_n=3.0e5 --set contact.k_t=6.0e4 --set contact.rolling_stiffness=1.2e5 \
      "${ISOTROPIC_ONLY[@]}" --set protocol.save_path_states=true "$@"
  done
}
k0_from_run() {
  local name=$1 start
  [[ -n $ONLY && ! $name =~ $ONLY ]] && return
  [ -f "$OUT/$name/summary.json" ] && [ ! -f "$OUT/${name}_k0.json" ] || return
  start=$(date +%s)
  "$PY" "$(dirname "${BASH_SOURCE[0]}")/paired_paths.py" --from-run "$OUT/$name" \
    --variant "k0=protocol.run_k0=true;protocol.run_unloading=true;probing.states=A, B, C, B'" \
    --branches k0 --workers 1 --out "$OUT/${name}_k0.json" > "$OUT/${name}_k0.log" 2>&1
  echo "${name}_k0 rc $? wall $(( $(date +%s) - start )) s" >> "$OUT/summary.txt"
}
