"""The stated mapping between the DEM's 2D results and the TIV model's 3D tensors:
:class:`Convention` (used both ways: DEM → model series by :mod:`bridge.series`, model → DEM
datasets by its inverse functions), and :class:`SeriesError`, the error of results that cannot be
turned into model series. :mod:`bridge.series` re-exports both.

Conventions (:class:`Convention`)
---------------------------------
Stress (DEM σ_v = σ_yy, σ_h = σ_xx, compression positive, times the stated ``stress_scale_kpa``):

* ``"triaxial"`` (default, the study's "triaxial counterpart"): vertical DEM axis = axial,
  horizontal = both radial axes, σ_a = S σ_v, σ_r = S σ_h, hence p = (σ_a + 2σ_r)/3 and
  q = σ_a − σ_r.
* ``"plane"`` (2D-consistent alternative): the model's invariants take the DEM's 2D values,
  p = S (σ_v + σ_h)/2 and q = S (σ_v − σ_h); the model's triaxial components are then
  σ_a = p + 2q/3, σ_r = p − q/3. Inverse: σ_v = (p + q/2)/S, σ_h = (p − q/2)/S.

Fabric: the model's β is signed like the stress deviator (positive when the major stress is
vertical), the DEM rod-orientation deviator β_yy − β_xx is negative when rods lie down under a
vertical load, so β_model = −F (β_yy − β_xx) with the stated ``fabric_scale`` F (default 1). The
same map is used in both conventions.

Elastic moduli: the DEM's 2D stiffness C_ij (Voigt xx, yy, xy) is identified with the in-plane
block of the model's elastic stiffness D (kPa): E_oed,v = C_yyyy ↔ D_aaaa, E_oed,h = C_xxxx ↔
D_rrrr, C_xxyy ↔ D_raaa... i.e. the cross term C_12 ↔ D_ra. This is exact for a plane-strain
reading (ε_zz = 0) as well, so it is the same in both conventions; moduli scale with S.

Symbols: S stress scale (kPa per DEM stress unit), F fabric scale (1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["CONVENTIONS", "Convention", "SeriesError"]

#: The allowed 2D → 3D conventions.
CONVENTIONS = ("triaxial", "plane")


class SeriesError(ValueError):
    """DEM results that cannot be turned into model series (missing variable, path, scale)."""


@dataclass(frozen=True)
class Convention:
    """The stated mapping between DEM results and the TIV model (see the module docstring).

    name: ``"triaxial"`` (default) or ``"plane"``;
    stress_scale_kpa: S, kPa per DEM stress unit (force/length), > 0; no default on purpose;
    fabric_scale: F in β_model = −F (β_yy − β_xx), > 0 (default 1).
    """

    stress_scale_kpa: float
    name: str = "triaxial"
    fabric_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.name not in CONVENTIONS:
            raise SeriesError(f"convention {self.name!r} is not allowed; use one of {CONVENTIONS}")
        for key in ("stress_scale_kpa", "fabric_scale"):
            value = getattr(self, key)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise SeriesError(f"{key} must be a number > 0, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise SeriesError(f"{key} = {value!r} must be a finite number > 0")
            object.__setattr__(self, key, float(value))

    # -- stress ----------------------------------------------------------------------------
    def model_stress(self, stress_yy, stress_xx) -> tuple[np.ndarray, np.ndarray]:
        """(σ_a, σ_r) in kPa of DEM (σ_yy, σ_xx) in DEM units."""
        sv = np.asarray(stress_yy, dtype=float) * self.stress_scale_kpa
        sh = np.asarray(stress_xx, dtype=float) * self.stress_scale_kpa
        if self.name == "triaxial":
            return sv, sh
        p = 0.5 * (sv + sh)
        q = sv - sh
        return p + 2.0 * q / 3.0, p - q / 3.0

    def dem_stress(self, axial, radial) -> tuple[np.ndarray, np.ndarray]:
        """(σ_yy, σ_xx) in DEM units of model (σ_a, σ_r) in kPa (inverse of ``model_stress``)."""
        sa = np.asarray(axial, dtype=float)
        sr = np.asarray(radial, dtype=float)
        if self.name == "triaxial":
            sv, sh = sa, sr
        else:
            p = (sa + 2.0 * sr) / 3.0
            q = sa - sr
            sv, sh = p + 0.5 * q, p - 0.5 * q
        return sv / self.stress_scale_kpa, sh / self.stress_scale_kpa

    # -- fabric ----------------------------------------------------------------------------
    def model_fabric(self, fabric_deviator) -> np.ndarray:
        """β_model = −F (β_yy − β_xx)."""
        return -self.fabric_scale * np.asarray(fabric_deviator, dtype=float)

    def dem_fabric(self, fabric) -> np.ndarray:
        """β_yy − β_xx = −β_model / F (inverse of :meth:`model_fabric`)."""
        return -np.asarray(fabric, dtype=float) / self.fabric_scale

    # -- moduli ----------------------------------------------------------------------------
    def model_modulus(self, modulus) -> np.ndarray:
        """A DEM modulus (force/length) in kPa."""
        return np.asarray(modulus, dtype=float) * self.stress_scale_kpa

    def dem_modulus(self, modulus) -> np.ndarray:
        """A model modulus (kPa) in DEM units."""
        return np.asarray(modulus, dtype=float) / self.stress_scale_kpa

    def attrs(self) -> dict[str, object]:
        """Dataset attributes that state the convention."""
        stress = (
            "sigma_a = S sigma_yy, sigma_r = S sigma_xx, p = (sigma_a + 2 sigma_r)/3, "
            "q = sigma_a - sigma_r"
            if self.name == "triaxial"
            else "p = S (sigma_yy + sigma_xx)/2, q = S (sigma_yy - sigma_xx), "
            "sigma_a = p + 2q/3, sigma_r = p - q/3"
        )
        return {
            "convention": self.name,
            "convention_stress": stress,
            "stress_scale_kpa": self.stress_scale_kpa,
            "convention_fabric": "beta_model = -fabric_scale (beta_yy - beta_xx), signed like q",
            "fabric_scale": self.fabric_scale,
            "convention_moduli": "E_oed,v = C_yyyy <-> D_aaaa, E_oed,h = C_xxxx <-> D_rrrr, "
            "C_xxyy <-> D_ra; kPa = S x DEM units",
        }
