"""How the engine fails: :class:`BlowUpError`, :class:`CapacityError` and their messages.

Every message names the likely cause and the setting to change (plain Python, no Taichi).
"""

from __future__ import annotations

from dem_taichi.kernels import layout as L
from dem_taichi.scene.config import Integration

__all__ = ["BlowUpError", "CapacityError", "blowup_error", "runaway_kinetic_energy"]


class BlowUpError(RuntimeError):
    """The run became unstable; the message names the likely cause and the fix."""


class CapacityError(RuntimeError):
    """An array capacity could not be grown; the message says what to set."""


def _dt_fix(integration: Integration) -> str:
    safety = integration.dt_safety
    return f"reduce [integration] dt_safety from {safety:g} to <= {round(safety * 0.67, 3):g}"


def blowup_error(code: int, index: int, step: int, integration: Integration) -> BlowUpError:
    """The error for a kernel's blow-up flag ``code`` (``layout.BLOWUP_*``) raised by rod or disc
    ``index`` at ``step``."""
    fix = _dt_fix(integration)
    if code == L.BLOWUP_NONFINITE:
        return BlowUpError(
            f"non-finite position or velocity of rod {index} at step {step}: the time step is "
            f"too large for the stiffest interaction or a parameter is invalid; {fix}"
        )
    bound = integration.max_overlap
    return BlowUpError(
        f"overlap beyond the bound max_overlap = {bound:g} d at disc {index}, step {step}: "
        f"contacts are too soft for the loading or the time step is too large; {fix}, lower "
        "the strain rate ([control] inertial_number_max or compression_strain_rate) or raise "
        "[contact] k_n"
    )


def runaway_kinetic_energy(
    kinetic_energy: float, limit: float, step: int, integration: Integration
) -> BlowUpError:
    """The error for a kinetic energy above ``limit`` (max_kinetic_energy_per_rod × N)."""
    safety = integration.dt_safety
    return BlowUpError(
        f"runaway kinetic energy {kinetic_energy:.3g} > {limit:.3g} (max_kinetic_energy_per_rod x "
        f"n_rods) at step {step}: the integration is unstable; reduce "
        f"[integration] dt_safety from {safety:g} to <= {round(safety * 0.67, 3):g} or "
        "raise local_damping / e_n damping"
    )
