"""Scene configuration: TOML file -> frozen dataclasses, validated at load.

A scene is a TOML file with one table per section. Each section maps to one frozen dataclass below;
each field carries its allowed range or choices in ``metadata`` and a generic loader checks types,
ranges and unknown keys, failing with a :class:`SceneError` that names the key and what is allowed.

Sections (units: dimensionless DEM units, d = disc diameter, m = disc mass):

``[scene]``         name, seed, description, preset (fast|balanced|accurate: a group of the
                    numerical keys, :mod:`dem_taichi.scene.presets`; keys written in the file win)
``[particles]``     n_rods, n_spheres, diameter d, spacing, disc_mass m, initial_area_fraction,
                    initial_speed (rms of the random gas velocity components), rod_model
                    (``"rigid"`` clumps, default, or ``"bonded"`` chains of disc bodies)
``[bonds]``         bonded rods only (docs/science/dem-model.md §1.7): normal, shear, bending
                    (k_bn/k_n, k_bt/k_n, κ_b/(k_n d²)), damping_ratio, breakage_force
``[contact]``       k_n, e_n *or* gamma_n, restitution_model (discrete|continuous), k_t, gamma_t,
                    mu, friction (on/off); optional rolling resistance at inter-rod contacts:
                    rolling_stiffness k_r (0: off), rolling_friction μ_r, rolling_damping γ_r
                    (:mod:`dem_taichi.physics.rolling`)
``[long_range]``    enabled, pattern (acidic|basic|neutral), f_max_edge, f_max_inner, k_a_edge,
                    k_a_inner
``[van_der_waals]`` enabled, f_max, k
``[integration]``   dt_safety, local_damping, steps_per_call, skin, execution, blow-up limits
``[control]``       inertial_number_max, compression_strain_rate, target_specific_volume,
                    relax_steps (the engine's built-in compression run); ``servo_gain`` (of
                    the engine's stress servo, removed) is accepted and dropped, so that older
                    scenes and checkpoints still load
``[output]``        every, checkpoint_every

Extension sections: ``[protocol]`` (:mod:`dem_taichi.scene.protocol_sections`) and ``[probing]``
(:mod:`dem_taichi.scene.probing_sections`) are known to every loader; other code may add more with
``register_section(name, cls)``. A loaded extension is found in ``scene.extensions[name]``. The core
sections' dataclasses are in :mod:`dem_taichi.scene.sections` (re-exported here); the section base
(:class:`SceneSection`, :class:`SceneError`) lives in :mod:`dem_taichi.scene.base`, below both.

Symbols: k_n normal stiffness, γ_n normal damping, e_n normal restitution, t_c contact duration
(two discs of mass m): t_c = π / sqrt(2 k_n/m − (γ_n/m)²), e_n = exp(−γ_n t_c / m).

Normal damping from a restitution (``[contact] e_n``; a scene giving ``gamma_n`` uses it as is and
ignores ``restitution_model``):

* The time step is Δt = dt_safety × t_c with t_c the contact duration of the *continuous* model
  for the target e_n (γ_c = γ_n of the formula above). It depends on neither the model choice nor
  the γ_n finally used, so Δt is deterministic and the same for both models (no fixed point).
* ``restitution_model = "continuous"``: γ_n = γ_c. The engine's leapfrog update with the dashpot
  on the stored half-step velocity then realises a different restitution, O(Δt/t_c): the mean
  over contact phases is −13 % (e_n = 0.3) to +0.1 % (e_n = 0.9) at dt_safety 0.15.
* ``restitution_model = "discrete"`` (default): γ_n is the root, at the scene's Δt, of
  ``restitution.discrete_restitution(γ_n) = e_n``, a host replica of the engine's own discrete
  two-disc collision averaged over the contact phase (module :mod:`dem_taichi.physics.restitution`).
  A single collision still scatters around e_n with its contact phase (at dt_safety 0.15:
  −18 … +48 % for e_n = 0.3, ±5 % for e_n = 0.9; within 1 % only near dt_safety 0.005): that
  spread is a property of the time step, not of γ_n. Scenes whose e_n the discrete collision
  cannot reach at their Δt (small e_n with dt_safety ≳ 0.2) fail at load.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from clay_cli import first_control_character
from dem_taichi.scene import sections as scene_sections
from dem_taichi.scene.base import SceneError, SceneSection, read_text_file
from dem_taichi.scene.presets import fill_preset, set_keys
from dem_taichi.scene.probing_sections import ProbingConfig
from dem_taichi.scene.protocol_sections import ProtocolConfig
from dem_taichi.scene.sections import (
    Bonds,
    Contact,
    Control,
    Integration,
    LongRange,
    Output,
    Particles,
    SceneInfo,
    VanDerWaals,
)

# the time step's bounds, defined in scene/stability.py (importable from here, as before)
from dem_taichi.scene.stability import BONDED_DT_SAFETY_LIMIT as BONDED_DT_SAFETY_LIMIT
from dem_taichi.scene.stability import tangential_stiffness_limit as tangential_stiffness_limit

__all__ = [
    "SceneError",
    "SceneSection",
    "Scene",
    *scene_sections.__all__,  # the core sections, re-exported
    "load_scene",
    "scene_from_dict",
    "scene_with_overrides",
    "scene_from_toml",
    "scene_to_toml",
    "register_section",
    "builtin_scene_path",
    "contact_duration",
    "tangential_stiffness_limit",
    "gamma_from_restitution",
    "restitution_from_gamma",
]


_CORE_SECTIONS: dict[str, type[SceneSection]] = {
    "scene": SceneInfo,
    "particles": Particles,
    "bonds": Bonds,
    "contact": Contact,
    "long_range": LongRange,
    "van_der_waals": VanDerWaals,
    "integration": Integration,
    "control": Control,
    "output": Output,
}
# the virtual experiments' sections ([protocol], [probing]), known to every scene loader
_EXTENSION_SECTIONS: dict[str, type] = {"protocol": ProtocolConfig, "probing": ProbingConfig}


def register_section(name: str, cls: type) -> None:
    """Allow an extra ``[name]`` table in scenes, loaded into the frozen dataclass ``cls``.

    ``cls`` should derive from :class:`SceneSection` (to get the generic validation).
    """
    if name in _CORE_SECTIONS:
        raise ValueError(f"section [{name}] is a core section")
    _EXTENSION_SECTIONS[name] = cls


def contact_duration(k_n: float, gamma_n: float, mass: float) -> float:
    """Duration of a binary disc collision, t_c = π / sqrt(2k_n/m − (γ_n/m)²) (reduced mass m/2)."""
    w2 = 2.0 * k_n / mass - (gamma_n / mass) ** 2
    if w2 <= 0:
        raise SceneError(f"[contact] gamma_n = {gamma_n} is overdamped for k_n = {k_n}")
    return math.pi / math.sqrt(w2)


def gamma_from_restitution(e_n: float, k_n: float, mass: float) -> float:
    """γ_n giving restitution e_n for two discs of mass m: inverts e_n = exp(−γ_n t_c/m)."""
    if e_n >= 1.0:
        return 0.0
    ln_e = math.log(e_n)
    # e = exp(-γ t_c/m), t_c = π/sqrt(2k/m − γ²/m²)  =>  γ² = 2 k m ln²e / (π² + ln²e)
    return math.sqrt(2.0 * k_n * mass * ln_e**2 / (math.pi**2 + ln_e**2))


def restitution_from_gamma(gamma_n: float, k_n: float, mass: float) -> float:
    """e_n = exp(−γ_n t_c / m)."""
    return math.exp(-gamma_n * contact_duration(k_n, gamma_n, mass) / mass)


@dataclass(frozen=True)
class Scene:
    """A validated scene. ``source_text`` keeps the TOML it was read from (for provenance)."""

    scene: SceneInfo = field(default_factory=SceneInfo)
    particles: Particles = field(default_factory=Particles)
    bonds: Bonds = field(default_factory=Bonds)
    contact: Contact = field(default_factory=Contact)
    long_range: LongRange = field(default_factory=LongRange)
    van_der_waals: VanDerWaals = field(default_factory=VanDerWaals)
    integration: Integration = field(default_factory=Integration)
    control: Control = field(default_factory=Control)
    output: Output = field(default_factory=Output)
    extensions: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    source_text: str = field(default="", compare=False, repr=False)

    # Derived quantities -------------------------------------------------------------------
    @property
    def continuous_gamma_n(self) -> float:
        """γ_n of the continuous model: given, or e_n = exp(−γ_n t_c/m) inverted; 0 if neither."""
        c, p = self.contact, self.particles
        if c.gamma_n is not None:
            return c.gamma_n
        if c.e_n is not None:
            return gamma_from_restitution(c.e_n, c.k_n, p.disc_mass)
        return 0.0

    @property
    def gamma_n(self) -> float:
        """Normal damping γ_n the engine uses (module docstring: ``restitution_model``)."""
        c, p = self.contact, self.particles
        if c.gamma_n is None and c.e_n is not None and c.restitution_model == "discrete":
            from dem_taichi.physics.restitution import gamma_for_discrete_restitution

            return gamma_for_discrete_restitution(c.e_n, c.k_n, p.disc_mass, self.time_step)
        return self.continuous_gamma_n

    @property
    def contact_duration(self) -> float:
        """t_c of the target collision in the continuous model (uses :attr:`continuous_gamma_n`)."""
        return contact_duration(self.contact.k_n, self.continuous_gamma_n, self.particles.disc_mass)

    @property
    def bonded(self) -> bool:
        """Whether the rods are bonded chains (``[particles] rod_model = "bonded"``)."""
        return self.particles.rod_model == "bonded"

    @property
    def bond_parameters(self):
        """The bonds' springs and dashpots (:class:`dem_taichi.physics.bonds.BondParameters`)."""
        from dem_taichi.physics.bonds import BondParameters

        p, b = self.particles, self.bonds
        return BondParameters.from_ratios(
            self.contact.k_n, p.diameter, p.spacing, p.disc_mass, b.normal, b.shear,
            b.bending, b.damping_ratio, b.breakage_force,
        )  # fmt: skip

    @property
    def bond_period(self) -> float:
        """π/ω_max of one free bonded chain (inf for rigid rods): the bonds' analogue of t_c."""
        if not self.bonded:
            return math.inf
        from dem_taichi.physics.bonds import chain_max_frequency

        p, bonds = self.particles, self.bond_parameters
        omega = chain_max_frequency(
            p.n_spheres, p.spacing, p.disc_mass, p.diameter, bonds.k_n, bonds.k_t, bonds.k_b
        )
        return math.pi / omega

    @property
    def rolling_parameters(self):
        """The contacts' rolling spring as moments
        (:class:`dem_taichi.physics.rolling.RollingParameters`; ``enabled`` False without rolling
        resistance)."""
        from dem_taichi.physics.rolling import RollingParameters

        c = self.contact
        return RollingParameters.from_scene_keys(
            c.rolling_stiffness, c.rolling_friction, c.rolling_damping, self.particles.diameter
        )

    @property
    def rolling_period(self) -> float:
        """π/ω of the rolling spring between two free bodies (rods, or discs of bonded rods;
        inf without rolling resistance)."""
        from dem_taichi.physics.forcelaw import rod_inertia
        from dem_taichi.physics.rolling import rolling_period

        p = self.particles
        n_body = 1 if self.bonded else p.n_spheres  # the discs of one body
        inertia = rod_inertia(n_body, p.spacing, p.diameter, p.disc_mass)
        return rolling_period(self.rolling_parameters.stiffness, inertia)

    @property
    def time_step(self) -> float:
        """Δt = dt_safety × min(t_c, bond period, rolling period) (continuous-model t_c: the
        same for both restitution models; the bond period only for bonded rods, the rolling
        period only with rolling resistance)."""
        return self.integration.dt_safety * min(
            self.contact_duration, self.bond_period, self.rolling_period
        )

    def replace(self, **sections: Any) -> Scene:
        """Copy with whole sections replaced or with ``section={"key": value}`` updates.

        The copy passes the checks a scene file passes: each key's own, and those across
        sections (k_t within :func:`tangential_stiffness_limit` of k_n at ``dt_safety``, a
        finite time step, bonded ``dt_safety``, the acidic pattern's ``n_spheres`` >= 3):
        :class:`SceneError` naming the keys otherwise. Change keys that depend on each other in
        one call."""
        updates = {}
        for name, value in sections.items():
            if name not in _CORE_SECTIONS:
                raise SceneError(
                    f"replace({name}=...): no such section; allowed: {', '.join(_CORE_SECTIONS)}"
                )
            current = getattr(self, name)
            if isinstance(value, dict):
                _check_keys(type(current), name, value)
                value = dataclasses.replace(current, **value)
            updates[name] = value
        scene = dataclasses.replace(self, **updates, source_text="")
        _check_scene(scene)
        return scene

    def with_changes(self, **sections: dict) -> Scene:
        """Alias of :meth:`replace` taking ``section={"key": value}`` dicts."""
        return self.replace(**sections)


#: Keys of retired options: older scenes (and the checkpoints written from them) carry them; they
#: are dropped at load. ``[control] servo_gain`` was the gain of the engine's stress servo
#: (removed; the protocol's servo, ``[protocol] servo_*``, holds the stresses).
_RETIRED_KEYS: dict[str, tuple[str, ...]] = {"control": ("servo_gain",)}


def _check_keys(cls: type, name: str, table: dict) -> None:
    """Refuse keys of ``table`` that section ``[name]`` (dataclass ``cls``) does not have."""
    known = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - known)
    if unknown:
        raise SceneError(
            f"[{name}] unknown key(s) {', '.join(unknown)}; "
            f"allowed keys: {', '.join(sorted(known))}"
        )


def _load_section(cls: type, name: str, table: Any) -> Any:
    if not isinstance(table, dict):
        raise SceneError(f"[{name}] must be a table")
    table = {k: v for k, v in table.items() if k not in _RETIRED_KEYS.get(name, ())}
    _check_keys(cls, name, table)
    try:
        return cls(**table)
    except TypeError as exc:  # pragma: no cover - defensive
        raise SceneError(f"[{name}] {exc}") from exc


def scene_from_dict(data: dict, source_text: str = "") -> Scene:
    """Build a :class:`Scene` from a nested dict (as returned by ``tomllib``).

    A ``[scene] preset`` (:mod:`dem_taichi.scene.presets`) fills the keys of its group that ``data``
    does not give; the keys given win."""
    data = fill_preset(data)
    allowed = {**_CORE_SECTIONS, **_EXTENSION_SECTIONS}
    unknown = sorted(set(data) - set(allowed))
    if unknown:
        raise SceneError(
            f"unknown section(s) {', '.join('[' + u + ']' for u in unknown)}; allowed sections: "
            + ", ".join(sorted(allowed))
        )
    core = {
        name: _load_section(cls, name, data.get(name, {})) for name, cls in _CORE_SECTIONS.items()
    }
    if "bonds" in data and core["particles"].rod_model != "bonded":
        raise SceneError(
            "[bonds] is used only with [particles] rod_model = 'bonded' (this scene's rods are "
            f"{core['particles'].rod_model!r}): remove [bonds] or set rod_model = 'bonded'"
        )
    ext = {
        name: _load_section(cls, name, data[name])
        for name, cls in _EXTENSION_SECTIONS.items()
        if name in data
    }
    scene = Scene(**core, extensions=MappingProxyType(ext), source_text=source_text)
    _check_scene(scene)
    return scene


#: The keys the time step and the contacts' damping are computed from, named when one of those
#: derived quantities is not a finite positive number.
_TIME_STEP_KEYS = (
    "[contact] k_n, e_n | gamma_n, rolling_stiffness; [particles] disc_mass, diameter, "
    "spacing, n_spheres; [integration] dt_safety"
)


def _check_derived(scene: Scene) -> None:
    """Refuse a scene whose time step or contact duration is not a finite positive number
    (keys that are each in range but together overflow or vanish), naming the keys they come
    from rather than the first formula that fails."""
    try:
        values = {"contact duration": scene.contact_duration, "time step": scene.time_step}
    except (OverflowError, ZeroDivisionError) as exc:
        raise SceneError(
            f"the contact duration and time step of this scene cannot be computed ({exc}): "
            f"check {_TIME_STEP_KEYS}"
        ) from None
    for what, value in values.items():
        if not (math.isfinite(value) and value > 0.0):
            raise SceneError(
                f"the {what} of this scene is {value!r}, not a finite positive number: "
                f"check {_TIME_STEP_KEYS}"
            )


def _check_tangential_stiffness(scene: Scene) -> None:
    """Refuse a tangential spring too stiff for the time step
    (:func:`tangential_stiffness_limit`)."""
    c, dt_safety = scene.contact, scene.integration.dt_safety
    limit = tangential_stiffness_limit(dt_safety)
    if c.k_t > limit * c.k_n:
        raise SceneError(
            f"[contact] k_t = {c.k_t!r} is {c.k_t / c.k_n:.3g} × k_n = {c.k_n!r}: allowed "
            f"k_t/k_n <= {limit:.3g} at [integration] dt_safety = {dt_safety} (Δt follows k_n "
            "alone; a stiffer tangential spring is unstable; elastic discs have k_t/k_n = "
            "2(1-ν)/(2-ν), 2/3 to 1)"
        )


def _check_scene(scene: Scene) -> None:
    scene.contact_duration  # noqa: B018 - raises on overdamped γ_n
    _check_derived(scene)
    _check_tangential_stiffness(scene)
    try:
        scene.gamma_n  # noqa: B018 - solves the discrete restitution model once (cached)
    except ValueError as exc:
        raise SceneError(
            f"[contact] e_n = {scene.contact.e_n} with restitution_model = "
            f"{scene.contact.restitution_model!r}: {exc}"
        ) from exc
    p, lr = scene.particles, scene.long_range
    dt_safety = scene.integration.dt_safety
    if scene.bonded and dt_safety > BONDED_DT_SAFETY_LIMIT:
        raise SceneError(
            f"[integration] dt_safety = {dt_safety} is beyond the measured stability limit of "
            f"bonded rods, {BONDED_DT_SAFETY_LIMIT} (of the stiffest of the contact duration and "
            "the bond period; benchmarks/results/bonded_stability.csv): lower dt_safety "
            "(the built-in scenes use 0.15, paper_bonded 0.30)"
        )
    if lr.enabled and lr.pattern == "acidic" and p.n_spheres < 3:
        raise SceneError(
            f"[long_range] pattern = 'acidic' needs n_spheres >= 3 (edge and inner discs); "
            f"[particles] n_spheres = {p.n_spheres}"
        )
    for section in scene.extensions.values():
        check = getattr(section, "check_scene", None)
        if check is not None:  # an extension's checks against the rest of the scene
            check(scene)


def scene_from_toml(text: str) -> Scene:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"invalid TOML: {exc}") from exc
    return scene_from_dict(data, source_text=text)


def builtin_scene_names() -> list[str]:
    """The names of the scenes shipped with the package (``dem_taichi/scenes/*.toml``), sorted."""
    return sorted(p.stem for p in (Path(__file__).parents[1] / "scenes").glob("*.toml"))


def builtin_scene_path(name: str) -> Path:
    """Path of a scene shipped with the package (:func:`builtin_scene_names`)."""
    path = Path(__file__).parents[1] / "scenes" / f"{name}.toml"
    if not path.exists():
        raise SceneError(
            f"no built-in scene {name!r}; available: {', '.join(builtin_scene_names())}"
        )
    return path


def load_scene(path_or_name: str | Path) -> Scene:
    """Load a scene from a TOML path or a built-in scene name (:func:`builtin_scene_names`).

    A scene *file* must state its sample: an empty file, or one without ``[particles]``, is
    refused (it would otherwise run the defaults without a word); ``scene_from_dict`` and
    ``scene_from_toml`` still fill every missing section with its defaults.
    """
    if not isinstance(path_or_name, str | Path) or not str(path_or_name).strip():
        raise SceneError(
            f"scene = {path_or_name!r}: give a built-in scene name "
            f"({', '.join(builtin_scene_names())}), a scene TOML path or a loaded Scene"
        )
    path = Path(path_or_name)
    if not path.exists() and path.suffix == "" and len(path.parts) == 1:
        path = builtin_scene_path(str(path_or_name))
    if not path.exists():
        raise SceneError(
            f"scene file {str(path)!r} does not exist; give a TOML file or a built-in scene "
            f"({', '.join(builtin_scene_names())})"
        )
    if not path.is_file():
        raise SceneError(f"scene {str(path)!r} is a directory; give a scene TOML file")
    text = read_text_file(path, "scene file")
    scene = scene_from_toml(text)
    if "particles" not in tomllib.loads(text):
        what = "is empty" if not text.strip() else "has no [particles] section"
        raise SceneError(
            f"scene file {str(path)!r} {what}: a scene states its sample ([particles] n_rods, "
            "n_spheres, ...); add [particles], or start from a built-in scene "
            "(dem_taichi/scenes/smoke.toml)"
        )
    return scene


def scene_with_overrides(scene: Scene, overrides: list[str] | tuple[str, ...]) -> Scene:
    """The scene with ``section.key=value`` overrides applied (e.g. ``contact.mu=0.2``,
    ``protocol.radial_stress_ratios="0.3"``), validated as a scene file is: an unknown section
    or key, or an invalid value, fails naming it and what is allowed. Values are read as TOML
    values (numbers, booleans, quoted strings); a bare word is taken as a string.
    ``scene.preset=NAME`` writes that preset's keys first; the other overrides win over it."""
    if not overrides:
        return scene
    data = tomllib.loads(scene_to_toml(scene))
    values: dict[str, Any] = {}
    for item in overrides:
        key, value = _parse_override(item)
        values[key] = value
    set_keys(data, values)
    rigid = data.get("particles", {}).get("rod_model", "rigid") != "bonded"
    if rigid and not any(item.strip().startswith("bonds.") for item in overrides):
        data.pop("bonds", None)  # a bonded scene made rigid by --set: its [bonds] no longer apply
    return scene_from_dict(data, source_text="")


def _parse_override(item: str) -> tuple[str, Any]:
    """``"section.key=value"`` → ``("section.key", value)``: the value is one TOML value (a
    number, boolean, quoted string or array), or else a bare word taken as a string. A line
    break or other control character (tab aside) anywhere is refused: TOML read what follows a
    line break as further keys, which were then dropped without a word."""
    if not isinstance(item, str):
        raise SceneError(f"--set {item!r}: expected a string section.key=value")
    bad = first_control_character(item, allow="\t")
    if bad is not None:
        raise SceneError(
            f"--set {item!r} contains the control character {bad!r} (a line break?): give "
            "one section.key=value per --set, on one line"
        )
    name, sep, text = item.partition("=")
    section, dot, key = name.strip().partition(".")
    if not sep or not dot or not section or not key.strip():
        raise SceneError(
            f"--set {item!r}: expected section.key=value (e.g. contact.mu=0.2 or scene.seed=4)"
        )
    try:
        value = tomllib.loads(f"v = {text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = text.strip()  # a bare word, e.g. particles.rod_model=bonded
    return f"{section}.{key.strip()}", value


def _toml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    raise TypeError(f"cannot write {value!r} to TOML")


#: Keys written only when set (not 0 / empty): options added after run directories and sweeps
#: began to hash the scene's TOML, so that a scene without them keeps its text and hash.
_WRITTEN_WHEN_SET = {
    ("scene", "preset"),
    ("contact", "rolling_stiffness"),
    ("contact", "rolling_friction"),
    ("contact", "rolling_damping"),
}


def scene_to_toml(scene: Scene) -> str:
    """Write the full scene (every key, defaults included) as TOML; round-trips exactly.

    ``[scene] preset`` and the rolling-resistance keys of ``[contact]`` are written only when
    set (:data:`_WRITTEN_WHEN_SET`; a preset's keys are all written anyway): a scene without
    them keeps the TOML (and the hash in run directories and sweeps) it had before they
    existed."""
    lines = []
    sections = {name: getattr(scene, name) for name in _CORE_SECTIONS}
    if not scene.bonded:
        del sections["bonds"]  # read only with bonded rods (and refused otherwise)
    sections.update(scene.extensions)
    for name, section in sections.items():
        lines.append(f"[{name}]")
        for f in dataclasses.fields(section):
            value = getattr(section, f.name)
            if value is None or ((name, f.name) in _WRITTEN_WHEN_SET and not value):
                continue
            lines.append(f"{f.name} = {_toml_value(value)}")
        lines.append("")
    return "\n".join(lines)
