"""Taichi kernels of the DEM engine (Taichi only; every input is an explicit ndarray argument).

- :mod:`.layout`: index constants of the small parameter/state/flag arrays (plain Python);
- :mod:`.laws`: pair force laws as ``ti.func`` (contact, long range, van der Waals);
- :mod:`.step`: neighbour lists, the fused multi-step kernel, per-step parallel kernels, measures.
"""
