"""The sections of a scene that set how discs of different rods, and the discs of a bonded
rod, interact: ``[contact]``, ``[bonds]``, ``[long_range]``, ``[van_der_waals]`` (frozen
dataclasses; :mod:`dem_taichi.scene.sections` re-exports them with the other core sections).

Each field carries its allowed range or choices, its unit and a one-line description in
``metadata`` (:mod:`dem_taichi.scene.base`), as in :mod:`dem_taichi.scene.sections`.

Units: DEM units, disc diameter d = 1 (length), disc mass m = 1 (mass), the scene's time unit;
a 2D stiffness is a force per length; "1" is a dimensionless number, "-" a text or a switch.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from dem_taichi.scene.base import SceneError, SceneSection
from dem_taichi.scene.base import field_choices as _choices
from dem_taichi.scene.base import field_doc as _doc
from dem_taichi.scene.base import field_range as _range

__all__ = ["Contact", "Bonds", "LongRange", "VanDerWaals"]


@dataclass(frozen=True)
class Contact(SceneSection):
    """``[contact]``: the linear spring–dashpot contact between discs of different rods, its
    Coulomb friction and the optional rolling resistance (:mod:`dem_taichi.physics.rolling`)."""

    SECTION = "contact"
    k_n: float = field(
        default=1.0e5,
        metadata=_range(
            0.0, None, lo_open=True, doc="normal contact stiffness k_n", unit="force/length"
        ),
    )
    e_n: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                1.0,
                lo_open=True,
                doc="normal coefficient of restitution e_n of a two-disc collision (sets γ_n; "
                "give e_n or gamma_n; neither: no normal damping)",
                unit="1",
            ),
            "optional": True,
        },
    )
    gamma_n: float | None = field(
        default=None,
        metadata={
            **_range(
                0.0,
                doc="normal damping coefficient γ_n, used as given (instead of e_n)",
                unit="force·time/length",
            ),
            "optional": True,
        },
    )
    restitution_model: str = field(
        default="discrete",
        metadata=_choices(
            "discrete",
            "continuous",
            doc="how γ_n follows from e_n: 'discrete' calibrates γ_n on the engine's own "
            "leapfrog collision at the scene's Δt (phase-averaged e_n exact); 'continuous' "
            "uses e_n = exp(−γ_n t_c/m) (realised e_n off by O(Δt/t_c)); unused with gamma_n",
            unit="-",
        ),
    )
    k_t: float = field(
        default=2.0e4,
        metadata=_range(
            0.0,
            doc="tangential spring stiffness k_t; k_t/k_n at most the leapfrog bound of "
            "dt_safety (6.0 at 0.15)",
            unit="force/length",
        ),
    )
    gamma_t: float = field(
        default=0.0,
        metadata=_range(0.0, doc="tangential damping coefficient γ_t", unit="force·time/length"),
    )
    mu: float = field(
        default=0.5,
        metadata=_range(
            0.0,
            doc="Coulomb friction coefficient μ: the tangential force capped at μ|f_n|",
            unit="1",
        ),
    )
    friction: bool = field(
        default=True,
        metadata=_doc("tangential spring and Coulomb friction on (false: frictionless)", "-"),
    )
    rolling_stiffness: float = field(
        default=0.0,
        metadata=_range(
            0.0,
            None,
            doc="k_r of the rolling spring at inter-rod contacts, moment "
            "stiffness k_r (d/2)² (MercuryDPM's; dem_taichi.physics.rolling); "
            "0: no rolling resistance",
            unit="force/length",
        ),
    )
    rolling_friction: float = field(
        default=0.0,
        metadata=_range(
            0.0, None, doc="μ_r: rolling moment cap μ_r (d/2) |f_c|; > 0 with k_r", unit="1"
        ),
    )
    rolling_damping: float = field(
        default=0.0,
        metadata=_range(
            0.0,
            None,
            doc="γ_r of the rolling dashpot: moment damping γ_r (d/2)² ω_rel",
            unit="force·time/length",
        ),
    )
    cap_force: str = field(
        default="contact",
        metadata=_choices(
            "contact",
            "net",
            "net_after_A",
            doc="the normal force behind the sliding cap μ|f| and the rolling cap μ_r (d/2)|f| "
            "at inter-rod contacts: 'contact' the contact spring's force f_c, which the "
            "attraction loads (MercuryDPM's laws, as in the study); 'net' max(f_c − F_att, 0), "
            "F_att the pair's attraction (long-range and van der Waals): the attraction holds "
            "a contact shut but adds no strength (a departure from the study's laws); "
            "'net_after_A' the study's caps up to state A, 'net' from A on (a diagnostic: every "
            "joint of the gel loses the attraction's share of its strength at A)",
            unit="-",
        ),
    )

    def check(self) -> None:
        if self.e_n is not None and self.gamma_n is not None:
            raise SceneError("[contact] give either e_n or gamma_n, not both")
        if self.rolling_stiffness > 0.0 and self.rolling_friction <= 0.0:
            raise SceneError(
                f"[contact] rolling_stiffness = {self.rolling_stiffness} needs rolling_friction "
                "> 0 (the moment cap μ_r (d/2) |f_c|; a large value, e.g. 1e6, never slips)"
            )
        if self.rolling_stiffness == 0.0 and (self.rolling_friction or self.rolling_damping):
            raise SceneError(
                "[contact] rolling_friction / rolling_damping are used only with "
                "rolling_stiffness > 0 (rolling resistance off): set rolling_stiffness or "
                "remove them"
            )


@dataclass(frozen=True)
class Bonds(SceneSection):
    """Intra-rod bonds of ``rod_model = "bonded"`` (docs/science/dem-model.md §1.7; law in
    :mod:`dem_taichi.physics.bonds`), as ratios to the contact stiffness k_n.

    Defaults: k_bn = k_n and k_bt = 0.2 k_n (the scenes' k_t/k_n), κ_b = 0.3 k_n d² (the
    stiffness-anisotropy experiments' range 0.3–1; 0.1 is at the buckling edge at p = 100);
    damping ratio 0.2 (near the contacts' e_n = 0.5, ζ = 0.215); unbreakable.
    """

    SECTION = "bonds"
    normal: float = field(
        default=1.0,
        metadata=_range(
            0.0, None, lo_open=True, doc="k_bn / k_n: stiffness of the bond's stretch", unit="1"
        ),
    )
    shear: float = field(
        default=0.2,
        metadata=_range(
            0.0, None, lo_open=True, doc="k_bt / k_n: stiffness of the bond's shear", unit="1"
        ),
    )
    bending: float = field(
        default=0.3,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="κ_b / (k_n d²): stiffness of the bond's bending",
            unit="1",
        ),
    )
    damping_ratio: float = field(
        default=0.2,
        metadata=_range(
            0.0,
            1.0,
            doc="damping ratio ζ of each bond mode, γ = 2ζ sqrt(k μ), μ = m/2 or I/2",
            unit="1",
        ),
    )
    breakage_force: float = field(
        default=0.0,
        metadata=_range(
            0.0,
            None,
            doc="tension F_b at which a bond breaks for good (0: unbreakable)",
            unit="force",
        ),
    )


@dataclass(frozen=True)
class LongRange(SceneSection):
    """``[long_range]``: the electro-chemical long-range forces between charged discs of
    different rods (docs/science/dem-model.md §1.2): a force F_max at contact falling linearly to
    0 at the gap g_max = F_max / k_a, its sign the product of the discs' charges.

    ``strength_spread`` σ > 0 gives the rods a distribution of strengths (a modelling option of
    ours, not the study's: its rods are all alike): rod r draws s_r = exp(σ z_r), z_r ~ N(0, 1)
    from its own random stream of the scene's seed (the gas is unchanged), and the s_r are
    divided by their mean; a pair of discs of rods a and b has F_max and k_a times
    2 s_a s_b / (s_a + s_b). Default 0 (rods alike).

    ``attraction_pairs = "bonded_at_A"`` (a modelling option of ours, not the study's, whose law
    is reversible) keeps the gel's bonds as they were at state A: from A on, an attractive pair
    (opposite charges) acts only between two rods that attracted each other at A; rods that meet
    later, or pairs of discs of unbonded rods, do not attract; repulsion is unchanged. Before A
    (the gas, its ageing and the compression to A) every pair attracts, so A is the same.
    Default ``"any"`` (the study's law: every opposite-charge pair within range attracts)."""

    SECTION = "long_range"
    enabled: bool = field(default=False, metadata=_doc("long-range forces on", "-"))
    pattern: str = field(
        default="acidic",
        metadata=_choices(
            "acidic",
            "basic",
            "neutral",
            doc="charges of the discs: 'acidic' edge discs +1, inner discs −1; 'basic' all "
            "−1; 'neutral' all 0 (no long-range force)",
        ),
    )
    f_max_edge: float = field(
        default=10.0,
        metadata=_range(
            0.0, None, lo_open=True, doc="F_max of a pair involving an edge disc", unit="force"
        ),
    )
    f_max_inner: float = field(
        default=10.0,
        metadata=_range(
            0.0, None, lo_open=True, doc="F_max of a pair of inner discs", unit="force"
        ),
    )
    k_a_edge: float = field(
        default=20.0,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="slope k_a of the force with the gap, pair involving an edge disc",
            unit="force/length",
        ),
    )
    k_a_inner: float = field(
        default=20.0,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="slope k_a of the force with the gap, pair of inner discs",
            unit="force/length",
        ),
    )
    strength_spread: float = field(
        default=0.0,
        metadata=_range(
            0.0,
            2.0,
            doc="spread σ of the rods' bond strengths: each rod draws s = exp(σ z), z ~ N(0, 1), "
            "rescaled to a mean of 1 over the rods; a pair's F_max and k_a are multiplied by "
            "the harmonic mean of its two rods' s, so the range g_max is kept. 0: every rod alike "
            "(costs nothing)",
            unit="-",
        ),
    )
    attraction_pairs: str = field(
        default="any",
        metadata=_choices(
            "any",
            "bonded_at_A",
            doc="which pairs of opposite charge attract: 'any' within range (the study's law); "
            "'bonded_at_A' from state A on only discs of two rods that attracted each other at A "
            "(no new bonds after A; repulsion unchanged; costs nothing when 'any')",
        ),
    )


@dataclass(frozen=True)
class VanDerWaals(SceneSection):
    """``[van_der_waals]``: an attraction between charged discs of different rods (both charges
    non-zero), whatever their signs: the long-range law with the sign −1
    (docs/science/dem-model.md §1.2)."""

    SECTION = "van_der_waals"
    enabled: bool = field(default=False, metadata=_doc("van der Waals attraction on", "-"))
    f_max: float = field(
        default=1.0,
        metadata=_range(0.0, None, lo_open=True, doc="attraction at contact F_max", unit="force"),
    )
    k: float = field(
        default=10.0,
        metadata=_range(
            0.0,
            None,
            lo_open=True,
            doc="slope of the attraction with the gap (range g_max = f_max / k)",
            unit="force/length",
        ),
    )
