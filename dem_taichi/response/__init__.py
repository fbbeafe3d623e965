"""The linear response of a static rod network: stiffness matrices, the rigid, flexible and
bonded probes, and where the stiffness anisotropy comes from (numpy/scipy).

Written against :class:`dem_taichi.physics.snapshot.NetworkSnapshot`; only
:mod:`~dem_taichi.response.anisotropy` reads checkpoints through the engine.
"""
