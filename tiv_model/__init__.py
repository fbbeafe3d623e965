"""Hyperplastic (TIV) anisotropic clay model: potentials, integration, element tests.

Usable on its own: this package imports neither Taichi nor ``dem_taichi`` nor ``bridge``.

Model (see docs/science/tiv-model.md §2): free energy φ = F(v) Ψ(ε̃) with a fabric-mapped
strain ε̃ (anisotropy form "A" or "B"), rotated-ellipse yield surface from the dissipation
function (with or without constraint forces), isotropic hardening of p_c through the specific
volume v, fabric β evolving towards a bounding fabric β_b (swappable law).

Modules
-------
params       Parameters (Table 1 preset ``TABLE1``), ModelOptions, SolverSettings, bound laws
tensors      Mandel helpers and invariants
energy       φ, σ = ∂φ/∂ε^e, closed-form stiffness D (general 3×3, batched), convexity check
dissipation  p_c, D̄, dissipation, yield function, flow direction, bounding fabric
state        frozen State of a material point
local_problem residuals of the implicit increment and their exact Jacobian (batched)
integrate    backward-Euler + Newton with line search, mixed control, substepping, typed errors
batch        many material points per strain increment in one batched Newton
triaxial     scalar axisymmetric fast path of the same equations, exact Jacobian (automatic)
triaxial_solver  its Newton solvers (one Newton for mixed control, the nested one as fallback)
drivers      element tests → xarray.Dataset along ``step``; elastic_probe
checks       reusable thermodynamic checks (FD stiffness, Legendre, loops, dissipation)
cli          ``python -m tiv_model`` / ``tiv-model`` command line

Example
-------
>>> from tiv_model import drivers
>>> ds = drivers.k0(100.0, increments=20)         # Table 1, form A, constraint forces
>>> round(float(ds.radial_stress[-1] / ds.axial_stress[-1]), 2)
0.66
"""

__version__ = "0.1.0"

from .errors import (  # noqa: E402
    ConvergenceError,
    NonConvexEnergyError,
    ParameterError,
    SpecificVolumeBelowOneError,
    TivModelError,
)
from .params import TABLE1, ModelOptions, Parameters, SolverSettings  # noqa: E402

__all__ = [
    "TABLE1",
    "ConvergenceError",
    "ModelOptions",
    "NonConvexEnergyError",
    "ParameterError",
    "Parameters",
    "SolverSettings",
    "SpecificVolumeBelowOneError",
    "TivModelError",
    "__version__",
]
