"""The scene resolved once into what the kernels are given: compile-time physics switches
(:class:`Physics`) and typed runtime parameters (:class:`EngineParameters`).

``params``, the kernels' runtime array, is generated from :class:`EngineParameters`: its slots are
the fields, in the order of :data:`dem_taichi.kernels.layout.PARAMETER_SLOTS` (the one table; the
kernels' ``P_*`` constants are derived from it, and a check below refuses a field list that
differs). ``params.vector(dtype)`` is the array, ``EngineParameters.from_vector`` reads one back
(a state's, or the device array's after run-time changes), ``with_changes`` and ``tuned`` change
values by name.

Symbols: Δt time step, k_n, γ_n normal stiffness and damping, k_t, γ_t tangential stiffness and
damping, μ Coulomb friction, α local damping, M, I mass and moment of inertia of a body, d disc
diameter, ε̇ cell strain rate, F_w, k_w van der Waals strength and stiffness, s_0 bond rest length,
k_bn, k_bt, κ_b, γ_bn, γ_bt, γ_bb bond stiffnesses and dampings, F_b bond strength, κ_r, η_r, μ_r
d_eff rolling stiffness, damping and cap. Units are the scene's (length in d, mass in m, time in
the scene's unit), as in docs/science/dem-model.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import Self

import numpy as np

from dem_taichi.kernels import layout as L
from dem_taichi.scene.config import Scene
from dem_taichi.scene.geometry import (
    RodGeometry,
    body_geometry,
    pair_table,
    rod_geometry,
    rod_strengths,
    species_parameters,
)

__all__ = [
    "TUNABLE_PARAMETERS",
    "EngineParameters",
    "Physics",
    "ResolvedScene",
    "interaction_cutoff",
    "resolve_parameters",
    "resolve_physics",
    "resolve_scene",
]


@dataclass(frozen=True)
class Physics:
    """Compile-time physics switches (a ``ti.template()``: physics switched off costs nothing).

    ``bonded``: bonded rods (every disc a body, :mod:`dem_taichi.kernels.bonds`); ``chain``: the
    discs per rod n_s (species by the place in the rod; for rigid rods also the discs per body);
    ``rolling``: rolling resistance at inter-rod contacts (:mod:`dem_taichi.physics.rolling`);
    ``strength``: the rods' long-range strengths differ (``[long_range] strength_spread`` > 0:
    :func:`dem_taichi.scene.geometry.rod_strengths`); ``partners``: from state A on, attraction
    only between rods that attracted each other at A (``[long_range] attraction_pairs =
    "bonded_at_A"``: :meth:`dem_taichi.engine.simulation.Simulation.freeze_attraction`);
    ``net_caps``: the sliding and rolling caps from the contact force less the pair's attraction
    (``[contact] cap_force = "net"`` or ``"net_after_A"``, with friction or rolling resistance
    and an attraction; with ``"net_after_A"`` the kernels compile it only from state A on,
    :meth:`dem_taichi.engine.simulation_state.SimulationState.kernel_physics`).
    """

    friction: bool
    long_range: bool
    vdw: bool
    bonded: bool = False
    chain: int = 1
    rolling: bool = False
    strength: bool = False
    partners: bool = False
    net_caps: bool = False


def resolve_physics(scene: Scene, charge: np.ndarray, n_spheres: int) -> Physics:
    """The switches of ``scene``: friction needs k_t > 0; the long-range and van der Waals laws
    need a charged species (``charge``, per place in the rod); ``n_spheres`` is n_s of a rod."""
    charged = bool(np.any(charge != 0))
    long_range = scene.long_range.enabled and charged
    vdw = scene.van_der_waals.enabled and charged
    friction = scene.contact.friction and scene.contact.k_t > 0
    rolling = scene.rolling_parameters.enabled
    return Physics(
        friction=friction,
        long_range=long_range,
        vdw=vdw,
        bonded=scene.bonded,
        chain=n_spheres,
        rolling=rolling,
        strength=long_range and scene.long_range.strength_spread > 0.0,
        partners=long_range and scene.long_range.attraction_pairs == "bonded_at_A",
        net_caps=(
            scene.contact.cap_force != "contact" and (long_range or vdw) and (friction or rolling)
        ),
    )


def interaction_cutoff(
    scene: Scene, diameter: float, physics: Physics, table: np.ndarray | None = None
) -> float:
    """The interaction cut-off (centre distance, in d): ``diameter``, plus the longest range of
    the long-range law among charged species pairs (``table``: the scene's
    :func:`dem_taichi.scene.geometry.pair_table`, computed when not given) and of the van der
    Waals law (F_w / k_w) when they are on."""
    reach = 0.0
    if physics.long_range:
        table = pair_table(scene) if table is None else table
        reach = max(reach, float(np.max(np.where(table[..., 0] != 0, table[..., 2], 0.0))))
    if physics.vdw:
        reach = max(reach, scene.van_der_waals.f_max / scene.van_der_waals.k)
    return diameter + reach


@dataclass(frozen=True)
class EngineParameters:
    """The runtime parameters of the kernels, one field per slot of ``params`` (same order as
    :data:`dem_taichi.kernels.layout.PARAMETER_SLOTS`). Changing one never recompiles."""

    time_step: float  #: Δt, time
    k_n: float  #: normal contact stiffness k_n, force / length
    gamma_n: float  #: normal contact damping γ_n, force × time / length
    k_t: float  #: tangential stiffness k_t (0 without friction), force / length
    gamma_t: float  #: tangential damping γ_t, force × time / length
    mu: float  #: Coulomb friction coefficient μ, 1
    local_damping: float  #: local non-viscous damping α, 1
    mass: float  #: mass M of a body (a rod, or a disc of a bonded rod), mass
    inertia: float  #: moment of inertia I of a body, mass × length²
    diameter: float  #: disc diameter d, length
    list_radius: float  #: neighbour-list radius: cut-off + skin (centre distance), length
    skin: float  #: Verlet skin, length
    vdw_f_max: float  #: van der Waals strength F_w, force
    vdw_k: float  #: van der Waals stiffness k_w, force / length
    rate_x: float  #: cell strain rate ε̇_xx = −L̇_x/L_x (compression positive), 1 / time
    rate_y: float  #: cell strain rate ε̇_yy, 1 / time
    max_offset: float  #: largest |o_s| of a disc from its body's centroid, length
    max_overlap: float  #: blow-up bound on the overlap δ (absolute), length
    reach: float  #: bound on the centroid branch vector of a listed pair, length
    cutoff: float  #: interaction cut-off (centre distance), length
    spacing: float  #: bond rest length s_0 (the rods' disc spacing), length
    bond_k_n: float  #: bond stretch stiffness k_bn (0 for rigid rods), force / length
    bond_k_t: float  #: bond shear stiffness k_bt, force / length
    bond_k_b: float  #: bond bending stiffness κ_b, force × length / radian
    bond_gamma_n: float  #: bond stretch damping γ_bn, force × time / length
    bond_gamma_t: float  #: bond shear damping γ_bt, force × time / length
    bond_gamma_b: float  #: bond bending damping γ_bb, force × length × time / radian
    bond_breakage_force: float  #: breakage tension F_b (≤ 0: unbreakable), force
    rolling_stiffness: float  #: κ_r = k_r d_eff², moment per radian of the rolling spring
    rolling_damping: float  #: η_r = γ_r d_eff², moment per unit relative rotation rate
    rolling_cap: float  #: μ_r d_eff, the rolling moment cap per unit contact force, length

    def vector(self, dtype: type[np.floating] | np.dtype = np.float64) -> np.ndarray:
        """The ``params`` array (N_PARAMS,) in ``dtype``: the fields in slot order, as float64
        first (then rounded once to ``dtype``)."""
        values = [getattr(self, name) for name in L.PARAMETER_SLOTS]
        return np.array(values, dtype=np.float64).astype(dtype)

    @classmethod
    def from_vector(cls, vector: np.ndarray) -> Self:
        """The parameters held by a ``params`` array of today's layout (a device array's copy or
        a state's, :func:`dem_taichi.engine.state.upgrade_state` brings older ones to it)."""
        values = np.asarray(vector)
        if values.shape != (L.N_PARAMS,):
            raise ValueError(
                f"params of shape {values.shape}: expected ({L.N_PARAMS},), the slots of "
                "dem_taichi.kernels.layout.PARAMETER_SLOTS"
            )
        return cls(**{name: float(v) for name, v in zip(L.PARAMETER_SLOTS, values, strict=True)})

    def with_changes(self, **values: float) -> Self:
        """A copy with the fields ``values`` names changed (a ``ValueError`` for an unknown
        name)."""
        unknown = sorted(set(values) - set(L.PARAMETER_SLOTS))
        if unknown:
            raise ValueError(
                f"unknown parameter {unknown[0]!r}; allowed: {', '.join(L.PARAMETER_SLOTS)}"
            )
        return replace(self, **{name: float(v) for name, v in values.items()})

    def tuned(self, **values: float) -> Self:
        """A copy with run-time changes of the :data:`TUNABLE_PARAMETERS` (the ones a protocol or
        a probe may change; each finite and ≥ 0), a ``ValueError`` naming the allowed ones
        otherwise."""
        for name, value in values.items():
            if name not in TUNABLE_PARAMETERS:
                raise ValueError(
                    f"unknown parameter {name!r}; allowed: {', '.join(sorted(TUNABLE_PARAMETERS))}"
                )
            if not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} = {value!r} must be finite and >= 0")
        return self.with_changes(**values)


#: The parameters :meth:`EngineParameters.tuned` (``Simulation.set_parameters``) may change at
#: run time; the others follow from the geometry, the list and the control.
TUNABLE_PARAMETERS: tuple[str, ...] = (
    "time_step",
    "k_n",
    "gamma_n",
    "k_t",
    "gamma_t",
    "mu",
    "local_damping",
)


def resolve_parameters(
    scene: Scene, body: RodGeometry, physics: Physics, list_radius: float, cutoff: float
) -> EngineParameters:
    """The runtime parameters of ``scene`` for bodies of geometry ``body`` (the rod, or one disc
    of a bonded rod), with the ``physics`` switches (k_t is 0 without friction; the bond
    parameters 0 for rigid rods), the neighbour-list radius ``list_radius`` and the interaction
    ``cutoff`` (both centre distances, length); the cell at rest (strain rates 0)."""
    s = scene
    bond = s.bond_parameters if physics.bonded else None
    roll = s.rolling_parameters
    return EngineParameters(
        time_step=s.time_step,
        k_n=s.contact.k_n,
        gamma_n=s.gamma_n,
        k_t=s.contact.k_t if physics.friction else 0.0,
        gamma_t=s.contact.gamma_t,
        mu=s.contact.mu,
        local_damping=s.integration.local_damping,
        mass=body.mass,
        inertia=body.inertia,
        diameter=body.diameter,
        list_radius=list_radius,
        skin=s.integration.skin,
        vdw_f_max=s.van_der_waals.f_max,
        vdw_k=s.van_der_waals.k,
        rate_x=0.0,
        rate_y=0.0,
        max_offset=body.max_offset,
        max_overlap=s.integration.max_overlap * body.diameter,
        reach=body.length + list_radius,
        cutoff=cutoff,
        spacing=s.particles.spacing,
        bond_k_n=bond.k_n if bond is not None else 0.0,
        bond_k_t=bond.k_t if bond is not None else 0.0,
        bond_k_b=bond.k_b if bond is not None else 0.0,
        bond_gamma_n=bond.gamma_n if bond is not None else 0.0,
        bond_gamma_t=bond.gamma_t if bond is not None else 0.0,
        bond_gamma_b=bond.gamma_b if bond is not None else 0.0,
        bond_breakage_force=bond.breakage_force if bond is not None else 0.0,
        rolling_stiffness=roll.stiffness,
        rolling_damping=roll.damping,
        rolling_cap=roll.cap,
    )


@dataclass(frozen=True)
class ResolvedScene:
    """What the engine takes from a scene, resolved once (:func:`resolve_scene`): the rod's
    ``geometry``, the ``body`` geometry (the rod, or one disc of a bonded rod), the ``species``
    (charge, F_max, k_a of each place in the rod: :func:`dem_taichi.scene.geometry.
    species_parameters`), the long-range law's ``pair_table`` of the species pairs
    (:func:`dem_taichi.scene.geometry.pair_table`), the compile-time ``physics``, the interaction
    ``cutoff`` and the neighbour-list radius ``list_radius`` (centre distances, length), the
    runtime ``parameters`` and the rods' strengths ``rod_strength`` ((N,), or None when the rods
    are alike: :func:`dem_taichi.scene.geometry.rod_strengths`)."""

    geometry: RodGeometry
    body: RodGeometry
    species: tuple[np.ndarray, np.ndarray, np.ndarray]
    pair_table: np.ndarray
    physics: Physics
    cutoff: float
    list_radius: float
    parameters: EngineParameters
    rod_strength: np.ndarray | None = None


def resolve_scene(scene: Scene) -> ResolvedScene:
    """The scene as the engine uses it: geometry, switches, cut-off and list radius (cut-off +
    ``[integration] skin``), runtime parameters (:class:`ResolvedScene`)."""
    geometry, body = rod_geometry(scene), body_geometry(scene)
    species = species_parameters(scene)
    table = pair_table(scene)
    physics = resolve_physics(scene, species[0], geometry.n_spheres)
    cutoff = interaction_cutoff(scene, geometry.diameter, physics, table)
    list_radius = cutoff + scene.integration.skin
    parameters = resolve_parameters(scene, body, physics, list_radius, cutoff)
    strength = rod_strengths(scene) if physics.strength else None
    return ResolvedScene(
        geometry, body, species, table, physics, cutoff, list_radius, parameters, strength
    )


def _check_slots() -> None:
    """Refuse, at import, a field list that is not the slot table (the kernels would read the
    wrong numbers)."""
    names = tuple(f.name for f in fields(EngineParameters))
    if names != L.PARAMETER_SLOTS:
        raise ImportError(
            "EngineParameters' fields differ from dem_taichi.kernels.layout.PARAMETER_SLOTS: "
            f"{names} != {L.PARAMETER_SLOTS}"
        )


_check_slots()
