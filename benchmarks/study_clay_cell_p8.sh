# Sourced by the issue-19 run scripts: the arguments of cell P8 on top of the `default` scene
# (RRn8 of study_clay_agitated.sh): F_max = 300, g_max = 0.5 d (k_a = 600), the pilots' slow gas,
# rolling resistance k_r = 4e4, mu_r = 0.5, a sparse gas (area fraction 0.10) aged 1000 time
# units at rms speed 0.5 by the resampling thermostat, 8 discs per rod, linear-response probes at
# every increment, no radial paths, no dynamic sweep. Defines the bash array p8_cell.
p8_cell=(--set particles.initial_speed=0.5 --set protocol.gas_strain_rate=0.002
         --set 'protocol.radial_stress_ratios=""' --set 'probing.dynamic_states=""'
         --set probing.every_n_increments=1
         --set long_range.f_max_edge=300 --set long_range.f_max_inner=300
         --set long_range.k_a_edge=600 --set long_range.k_a_inner=600
         --set contact.rolling_stiffness=4e4 --set contact.rolling_friction=0.5
         --set particles.initial_area_fraction=0.1 --set protocol.aggregation=time
         --set protocol.aggregation_time=1000 --set protocol.aggregation_speed=0.5
         --set particles.n_spheres=8)
