"""The numpy reference laws of the DEM model (bottom layer; imports nothing else of ``dem_taichi``).

The pair forces (:mod:`~dem_taichi.physics.forcelaw`: contact, tangential spring, long range,
van der Waals), rolling resistance (:mod:`~dem_taichi.physics.rolling`), the bonds of flexible
rods (:mod:`~dem_taichi.physics.bonds`), restitution (:mod:`~dem_taichi.physics.restitution`)
and the static network the linear-response probes read (:mod:`~dem_taichi.physics.snapshot`).
The Taichi kernels (:mod:`dem_taichi.kernels`) implement the same laws; the tests compare them.
"""
