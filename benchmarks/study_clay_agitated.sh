#!/bin/bash
# The study's-clay preparation runs of issue 19 (after study_clay_pilots.sh): what makes the gel
# loose. Base: the `default` scene (300 rods) with F_max = 300, g_max = 0.5 d (k_a = 600), the
# pilots' slow gas, no radial paths, linear-response probes at every increment. Cells:
#   RR        rolling resistance (k_r = 4e4, mu_r = 0.5), no aggregation stage
#   RRagg     RR + aggregation for 200 time units, the gas cooling freely (local damping)
#   RRaggv    RR + aggregation for 500 time units at a held rms speed 0.5 ("agitated")
#   aggv      the agitated aggregation without rolling resistance
#   RRaggv10  RRaggv from a sparser gas (area fraction 0.10) aged 1000 time units
# These agitated cells were run (2026-12-02, commits 63aa4c4 and cd4948c) with the thermostat that
# rescales every velocity by one factor, which pumps free-spinning rods (2 of 5 runs with rolling
# resistance stopped on an overlap); they keep it here (aggregation_thermostat = "rescale") to
# reproduce. Then, with the default thermostat since 50fb59a (fresh Maxwell velocities):
#   Raggv10   the sparser gas aged at rms speed 0.5, no rolling resistance
#   RRaggv10r the same with rolling resistance
#   RRfree10  rolling resistance, the sparser gas at initial speed 2.0 cooling freely (no thermostat)
# Then (2026-12-02, fourth session, from the commit that added them) the Langevin thermostat on
# RRaggv10's setting, so that one setting is seen under four ways of keeping the gas hot
# (rescale RRaggv10, resample RRaggv10r, free RRfree10, Langevin), its memory tau:
#   RRl10     tau = 10 time units (the check interval is 0.54: a = 0.947 per check)
#   RRl100    tau = 100 (a = 0.9946: close to free cooling with a slow refresh)
# Then longer rods (the study's aspect ratio is not public; its code used 5 discs), on
# RRaggv10r's setting (the resampling thermostat: no blow-up), 2 edge + (n - 2) inner discs:
#   RRn8      8 discs per rod
#   RRn10     10 discs per rod
# Then the cluster thermostat (aggregation_thermostat = "clusters": fresh centre-of-mass
# velocities of the clusters at the temperature, their insides not heated) on RRaggv10's setting:
#   RRc       rolling resistance, the sparser gas aged 1000 at speed 0.5 by clusters
# Run from a frozen clone of the commit to measure, one run at a time (2 cores). Then:
#   python benchmarks/study_clay_pilots.py OUT --out benchmarks/results/study_clay_agitated
#   usage: bash benchmarks/study_clay_agitated.sh OUT [PYTHON] [ONLY]
#   ONLY: a bash regular expression; only the runs whose name matches it (e.g. '^RRl')
set -u
common=(--set particles.initial_speed=0.5 --set protocol.gas_strain_rate=0.002
        --set 'protocol.radial_stress_ratios=""' --set 'probing.dynamic_states=""'
        --set probing.every_n_increments=1
        --set long_range.f_max_edge=300 --set long_range.f_max_inner=300
        --set long_range.k_a_edge=600 --set long_range.k_a_inner=600)
rr=(--set contact.rolling_stiffness=4e4 --set contact.rolling_friction=0.5)
agg=(--set protocol.aggregation=time --set protocol.aggregation_time=200)
aggv=(--set protocol.aggregation=time --set protocol.aggregation_time=500
      --set protocol.aggregation_speed=0.5 --set protocol.aggregation_thermostat=rescale)
loose=(--set particles.initial_area_fraction=0.1 --set protocol.aggregation=time
       --set protocol.aggregation_time=1000 --set protocol.aggregation_speed=0.5)
rescale=(--set protocol.aggregation_thermostat=rescale)
source "$(dirname "${BASH_SOURCE[0]}")/study_clay_run.sh"
run() {  # run NAME ARGS...: the default scene with the common arguments
  local name=$1; shift
  run_protocol "$name" default --quiet "${common[@]}" "$@"
}
run RRagg_s11 "${rr[@]}" "${agg[@]}" --set scene.seed=11
run RR_s11 "${rr[@]}" --set scene.seed=11
for seed in 11 2 12; do
  run RRaggv_s$seed "${rr[@]}" "${aggv[@]}" --set scene.seed=$seed
  run aggv_s$seed "${aggv[@]}" --set scene.seed=$seed
done
for seed in 11 2 12; do
  run RRaggv10_s$seed "${rr[@]}" "${loose[@]}" "${rescale[@]}" --set scene.seed=$seed
done
for seed in 11 2 12; do
  run RRaggv10r_s$seed "${rr[@]}" "${loose[@]}" --set scene.seed=$seed
  run Raggv10_s$seed "${loose[@]}" --set scene.seed=$seed
done
for seed in 11 2 12; do
  for tau in 10 100; do
    run RRl${tau}_s$seed "${rr[@]}" "${loose[@]}" --set protocol.aggregation_thermostat=langevin \
      --set protocol.aggregation_thermostat_time=$tau --set scene.seed=$seed
  done
done
for seed in 11 2 12; do
  run RRc_s$seed "${rr[@]}" "${loose[@]}" --set protocol.aggregation_thermostat=clusters \
    --set scene.seed=$seed
done
for n in 8 10; do
  for seed in 11 2 12; do
    run RRn${n}_s$seed "${rr[@]}" "${loose[@]}" --set particles.n_spheres=$n --set scene.seed=$seed
  done
done
for seed in 11 2 12; do
  run RRfree10_s$seed "${rr[@]}" --set particles.initial_speed=2.0 \
    --set particles.initial_area_fraction=0.1 --set protocol.aggregation=time \
    --set protocol.aggregation_time=1000 --set scene.seed=$seed
done
