"""The aggregation-stage keys of ``[protocol]``: their field metadata and their checks (issue 19).

The keys are fields of :class:`dem_taichi.scene.protocol_sections.ProtocolConfig` (declared there,
in the order the scene's TOML and hash have, from the metadata here); this module holds what only
they use, so that the ``[protocol]`` module stays one screenful of the paths' keys.

Preparation of the gas before the compression to A (issue 19): an attractive (clay-like)
gas left to aggregate before it is compressed forms clusters that jam much looser than the
gas compressed directly; the loose, attraction-stabilised structure is what collapses inside
the stress window (λ* ≈ 0.25). The stage "aggregation"
(:meth:`dem_taichi.protocol.paths.ProtocolRunner.aggregate`) runs before "isotropic_to_A" when
``aggregation`` is "time" or "coordination"; every key below is unset by default, so a scene
without them runs (and writes its TOML and hash) as before.

- ``aggregation`` [unset = "none"]: "none" — no stage; "time" — age the gas for
  ``aggregation_time``; "coordination" — age it until the mean coordination number
  Z = 2 n_contacts / n_rods (contacts per rod, the history's ``coordination_number``)
  reaches ``aggregation_coordination``, or stop at ``aggregation_max_time`` with a one-line
  note (not an error). Z is the criterion because the engine measures it at every check for
  free (the contact count is a by-product of the force loop); a mean cluster size would need
  a connected-components pass over the contact graph at every check.
- ``aggregation_time`` [unset; needed by "time"]: ageing time at fixed cell (DEM time units,
  d = m = 1; steps = ceil(time / Δt)).
- ``aggregation_coordination`` [unset; needed by "coordination"]: the Z that ends the
  ageing (contacts per rod; checked every ``relax_check_steps`` steps).
- ``aggregation_max_time`` [unset; needed by "coordination"]: the cap of the ageing time
  (DEM time units).
- ``aggregation_area_fraction`` [unset = the scene's [particles] initial_area_fraction, no
  compression]: the gas is first brought to this area fraction φ (solid area / cell area)
  by an isotropic strain-controlled compression at ``gas_strain_rate`` (over at least
  ``load_steps_min`` steps), then aged at that fixed cell. Allowed
  [initial_area_fraction, 1): a denser gas collides (and sticks) more often.
- ``aggregation_speed`` [unset = free cooling]: the rods' kinetic temperature during the
  ageing. Unset: none is imposed, the gas cools freely under the scene's damping (inelastic
  contacts, local damping, the attraction wells). Set: the rms velocity component of the
  bodies is brought to this value at the start of the ageing and after every check (every
  ``relax_check_steps`` steps), by ``aggregation_thermostat``; a speed far above
  sqrt(F_max g_max / m) breaks the contacts it forms (DEM velocity units).
- ``aggregation_thermostat`` [unset = "resample"; only with ``aggregation_speed``]: how.
  "resample" (an Andersen thermostat at every check): every body's velocity components
  are drawn afresh from N(0, speed²) and its angular velocity from N(0, speed² M/I)
  (equipartition), the mean velocity removed; the draws are seeded by the scene's seed and
  the step, so a run is deterministic and resumes bit for bit. "rescale": every velocity
  and angular velocity is multiplied by speed/rms, the factor of the whole gas. Rescaling
  by one factor pumps energy into the modes that lose none between checks (the "flying
  ice cube" of velocity rescaling, Harvey, Tan & Cheatham, J. Comput. Chem. 19 (1998) 726,
  doi:10.1002/(SICI)1096-987X(199805)19:7<726::AID-JCC4>3.0.CO;2-S): measured on the
  default scene with F_max = 300 and rolling resistance, one free-spinning rod went from
  ω = 2 to 50 in 20 checks and the run stopped on an overlap (4 of 12 runs with it
  stopped on a blow-up: ``benchmarks/results/study_clay_agitated.md``). Kept to reproduce
  the runs made with it. "langevin": a partial refresh at every check (the
  Ornstein–Uhlenbeck update over the check interval Δt), v ← a v + sqrt(1 − a²) ξ with
  a = exp(−Δt/τ), τ = ``aggregation_thermostat_time`` (needed by it, refused otherwise): each
  velocity and each cluster's collective motion lasts ~τ (τ → 0 is "resample"); the
  temperature is kept on average only where the gas loses little energy over τ, since each
  check puts back 1 − a² of it (measured on an ageing gel at τ = 10: kinetic energy per rod
  0.004 against ≈ 1.4 at the temperature asked);
  :func:`dem_taichi.protocol.quasistatic.refresh_speed`. "clusters": at every check each
  cluster of rods (joined by a contact or a long-range force) gets a fresh centre-of-mass
  velocity at the temperature (~N(0, speed²/n_c) per component for n_c rods), its rods' motion
  relative to it left alone, and a free rod a fresh spin: the clusters move as Brownian wholes
  and their insides are not heated; rigid rods only;
  :func:`dem_taichi.protocol.cluster_thermostat.cluster_speed`. "rods": at every check every
  rod gets a fresh rigid-body motion drawn as "resample" draws a rigid rod's (centre-of-mass
  velocity ~N(0, speed²) per component, the mean removed, angular velocity ~N(0, speed² M/I),
  M and I of the whole rod); the discs of a bonded rod are given its rigid-body velocity
  field v_i = V + Ω × (x_i − X) and ω_i = Ω, so the bonds' stretch, shear and bending rates are
  zero after each draw (where "resample" draws every disc on its own and heats the bonds); the
  rods' centre-of-mass rms component is ``aggregation_speed`` as for rigid rods. Rigid rods:
  "resample" itself, bit for bit; :func:`dem_taichi.protocol.rod_thermostat.rod_speed`.
- ``aggregation_time_step_factor`` [unset = 1; (0, 4]]: the ageing (not the compression of the
  gas before it) runs at this multiple of the scene's Δt, the scene's Δt restored after it. The
  thermostat's check interval is kept in time: ``relax_check_steps`` / factor steps (rounded,
  at least 1). A speed lever (issue 20): the ageing is a stochastic process whose thermostat
  redraws the velocities at every check, so what matters is the structure it builds, not the
  trajectory; a larger Δt resolves each collision with fewer steps (≈ 15 at dt_safety 0.15,
  ≈ 7 at twice that) and stays well inside the leapfrog stability bound. Measured at 2 on
  ``study_demo`` (three seeds, ``benchmarks/results/ageing_time_step.md``): not a lever. The
  coarse ageing built a less connected gel on every seed (Z at its end lower by 0.08–0.21)
  with K0 at C higher, and took 0.74–0.79 of the time, not half.
- ``aggregation_rod_model`` [unset = the scene's [particles] rod_model; "rigid" | "bonded"]:
  the rods the gas is compressed and aged as. "rigid" on bonded rods: both steps run on a rigid
  twin of the rods (the same discs, contacts, attraction, thermostat draws), at the rigid
  scene's Δt, which the contacts alone set (at k_n 3e5: 2.2 times the bonded Δt, which the
  bonds' period sets) with one body per rod; the rods are then handed back as straight bonded
  chains, their contacts' springs carried over or reset (``aggregation_springs``), and the
  compression to A follows on bonded rods (a speed lever of issue 20:
  :mod:`dem_taichi.protocol.rigid_ageing`). "rigid" on rigid rods is their own model;
  "bonded" needs bonded rods. With "rigid", the "clusters" thermostat is allowed on bonded rods.
  Measured on the bonded study cell KB300 (three seeds, criteria stated before the runs,
  ``benchmarks/results/ageing_rigid_rods.md``): the ageing in 0.14 of the time, the isotropic
  run in 0.31, but not the same material: K0 at C higher on every seed (+0.12 ± 0.16), λ* and
  the moduli exponent moved beyond the bonded cell's seed-to-seed spread; with the springs
  kept (``benchmarks/results/ageing_rigid_springs.md``, the same gels) λ* rose on every seed
  and K0 at C scattered: still not the bonded ageing's material. An option, not a default; no
  scene uses it.
- ``aggregation_springs`` [unset = "kept"; "kept" | "reset"]: with ``aggregation_rod_model =
  "rigid"`` on bonded rods, what the hand-over does with the gel's contacts. "kept": the
  tangential and rolling springs of the twin's contacts are carried to the same disc pairs of
  the bonded chains (the discs are numbered alike and sit where they sat, so each contact keeps
  its geometry and its spring); "reset": they start from zero (what the runs of
  ``ageing_rigid_rods.md`` had; its script sets it). Measured from the same gels
  (``ageing_rigid_springs.md``, three seeds): kept, λ* on the mapped window higher on every
  seed (+0.021 ± 0.024); K0 at C not consistently moved. Used only with "rigid".

Units: DEM units (d = 1, disc mass = 1); times in the scene's time unit. Every key's unit and a
one-line description are in its metadata (``unit=``, ``doc=``), from which the documentation's
scene reference is generated.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from dem_taichi.scene.base import SceneError
from dem_taichi.scene.base import field_choices as _choices
from dem_taichi.scene.base import field_range as _range

__all__ = ["AGGREGATION_KEYS", "check_aggregation_keys"]

#: key -> field metadata of each aggregation key of ``[protocol]`` (every one optional, unset by
#: default), in the order of the section's fields
AGGREGATION_KEYS: dict[str, dict[str, Any]] = {
    "aggregation": {
        **_choices(
            "none",
            "time",
            "coordination",
            doc=(
                "ageing of the gas before the compression to A: 'none' (unset), 'time',"
                " or until a mean coordination ('coordination')"
            ),
        ),
        "optional": True,
    },
    "aggregation_time": {
        **_range(
            0.0,
            None,
            lo_open=True,
            doc="ageing time at fixed cell (aggregation = 'time')",
            unit="time",
        ),
        "optional": True,
    },
    "aggregation_coordination": {
        **_range(
            0.0,
            None,
            lo_open=True,
            doc=(
                "mean coordination Z = 2 n_contacts / n_rods that ends the ageing "
                "(aggregation = 'coordination')"
            ),
            unit="1",
        ),
        "optional": True,
    },
    "aggregation_max_time": {
        **_range(
            0.0,
            None,
            lo_open=True,
            doc="cap of the ageing time (aggregation = 'coordination')",
            unit="time",
        ),
        "optional": True,
    },
    "aggregation_area_fraction": {
        **_range(
            0.0,
            1.0,
            lo_open=True,
            hi_open=True,
            doc=(
                "area fraction φ the gas is compressed to before the ageing (unset: the"
                " initial one, no compression)"
            ),
            unit="1",
        ),
        "optional": True,
    },
    "aggregation_speed": {
        **_range(
            0.0,
            None,
            lo_open=True,
            doc=(
                "rms velocity component the rods are kept at during the ageing, by "
                "aggregation_thermostat (unset: free cooling)"
            ),
            unit="length/time",
        ),
        "optional": True,
    },
    "aggregation_thermostat": {
        **_choices(
            "resample",
            "rescale",
            "langevin",
            "clusters",
            "rods",
            doc=(
                "how aggregation_speed is imposed: 'resample' (unset; Andersen: fresh"
                " Maxwell velocities at every check), 'rescale' (one factor for the"
                " whole gas), 'langevin' (a partial refresh at every check: the"
                " velocities keep their memory over aggregation_thermostat_time),"
                " 'clusters' (fresh centre-of-mass velocities of the clusters of rods,"
                " their insides left alone; rigid rods) or 'rods' (a fresh rigid-body"
                " motion of every rod, a bonded rod's discs moving with it; rigid rods:"
                " 'resample')"
            ),
        ),
        "optional": True,
    },
    "aggregation_thermostat_time": {
        **_range(
            0.0,
            None,
            lo_open=True,
            doc=(
                "correlation time τ of the 'langevin' thermostat's velocities (needed by"
                " it, refused otherwise)"
            ),
            unit="time",
        ),
        "optional": True,
    },
    "aggregation_time_step_factor": {
        **_range(
            0.0,
            4.0,
            lo_open=True,
            doc=(
                "the ageing's time step as a multiple of the scene's Δt (unset: 1); the"
                " thermostat's check interval is kept in time"
            ),
            unit="1",
        ),
        "optional": True,
    },
    "aggregation_rod_model": {
        **_choices(
            "rigid",
            "bonded",
            doc=(
                "the rods the gas is compressed and aged as (unset: the scene's rod_model);"
                " 'rigid' on bonded rods ages a rigid twin at its larger Δt, then hands the"
                " rods back as straight chains"
            ),
        ),
        "optional": True,
    },
    "aggregation_springs": {
        **_choices(
            "kept",
            "reset",
            doc=(
                "with aggregation_rod_model = 'rigid' on bonded rods: the contacts' tangential"
                " and rolling springs at the hand-over, carried from the rigid twin (unset:"
                " 'kept') or set to zero"
            ),
        ),
        "optional": True,
    },
}


def check_aggregation_keys(keys: Mapping[str, Any]) -> None:
    """Refuse (:class:`SceneError`, naming the key) aggregation keys that do not fit the
    criterion: each one the criterion needs is given, none is stray. ``keys``: every key of
    :data:`AGGREGATION_KEYS` with its value (``None`` when unset)."""
    mode = keys["aggregation"] or "none"
    needed = {
        "none": (),
        "time": ("aggregation_time",),
        "coordination": ("aggregation_coordination", "aggregation_max_time"),
    }[mode]
    for key in needed:
        if keys[key] is None:
            raise SceneError(f"[protocol] aggregation = {mode!r} needs {key} (not given)")
    criterion_keys = ("aggregation_time", "aggregation_coordination", "aggregation_max_time")
    stray = [k for k in criterion_keys if keys[k] is not None and k not in needed]
    if mode == "none":
        stray += [
            k
            for k in (
                "aggregation_area_fraction",
                "aggregation_speed",
                "aggregation_time_step_factor",
                "aggregation_rod_model",
                "aggregation_springs",
            )
            if keys[k] is not None
        ]
    thermostat, tau = keys["aggregation_thermostat"], keys["aggregation_thermostat_time"]
    if (thermostat == "langevin") != (tau is not None):
        raise SceneError(
            "[protocol] aggregation_thermostat_time is given with aggregation_thermostat = "
            f"'langevin' and only then (here: aggregation_thermostat = {thermostat!r}, "
            f"aggregation_thermostat_time = {tau!r})"
        )
    if thermostat is not None and keys["aggregation_speed"] is None:
        raise SceneError(
            f"[protocol] aggregation_thermostat = {thermostat!r} is used only with "
            "aggregation_speed (not given): set aggregation_speed or remove "
            "aggregation_thermostat"
        )
    if stray:
        uses = {
            "aggregation_time": "aggregation = 'time'",
            "aggregation_coordination": "aggregation = 'coordination'",
            "aggregation_max_time": "aggregation = 'coordination'",
        }
        key = stray[0]
        raise SceneError(
            f"[protocol] {key} = {keys[key]!r} is used only with "
            f"{uses.get(key, 'aggregation = time | coordination')}; this scene has "
            f"aggregation = {mode!r}: remove {key} or set aggregation"
        )
