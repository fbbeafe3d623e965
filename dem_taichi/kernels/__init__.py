"""Taichi kernels of the DEM engine (Taichi only; every input is an explicit ndarray argument).

- :mod:`.layout`: index constants of the small parameter/state/flag arrays, image codes and
  pair-flag bits (plain Python);
- :mod:`.laws`: long-range pair force laws as ``ti.func``;
- :mod:`.common`: annotations, ``sign``, disc placement;
- :mod:`.neighbours`: the Verlet list build and the rebuild criterion;
- :mod:`.pairs`: one pair's interaction (contact, friction, long range, van der Waals) and the
  force sum over a disc's list;
- :mod:`.step`: the fused multi-step kernel and the per-step parallel kernels;
- :mod:`.measures`: the measure kernel.

Kernel parameters are named after the device arrays of :mod:`dem_taichi.engine.device_arrays`.
"""
