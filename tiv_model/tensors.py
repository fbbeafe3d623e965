"""Second- and fourth-order tensor helpers (3x3 symmetric tensors, Mandel notation).

All functions accept a leading batch shape ``(...)``: a tensor is an array ``(..., 3, 3)``, its
Mandel vector an array ``(..., 6)`` and a fourth-order tensor with minor symmetries a Mandel
matrix ``(..., 6, 6)``.

Symbols
-------
p      mean stress, tr σ / 3 (kPa), compression positive
s      stress deviator, σ − p I (kPa)
q      deviatoric stress, sqrt(3/2 s:s) (kPa); triaxial q = σ_a − σ_r
ε_v    volumetric strain, tr ε
ε_s    deviatoric strain, sqrt(2/3 e:e); triaxial ε_s = 2/3 (ε_a − ε_r)
β_s    fabric invariant sqrt(3/2 β:β)

Mandel order: (11, 22, 33, 23, 13, 12), shear components multiplied by sqrt(2), so that the
double contraction a:b is the dot product of the Mandel vectors and a 4th-order tensor with minor
symmetries maps Mandel vectors by an ordinary matrix product. Index 0 is the axial (vertical)
direction of the element tests; 1 and 2 are radial (horizontal).
"""

from __future__ import annotations

import math

import numpy as np

SQRT2 = math.sqrt(2.0)
IDENTITY = np.eye(3)
#: Mandel vector of the identity tensor.
IDENTITY_MANDEL = np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
#: Mandel matrix of the deviatoric projector.
DEVIATORIC_PROJECTOR_MANDEL = np.eye(6) - np.outer(IDENTITY_MANDEL, IDENTITY_MANDEL) / 3.0
#: Unit triaxial deviator diag(2/3, -1/3, -1/3): its β_s (or q) is 1.
TRIAXIAL_DIRECTION = np.diag([2.0 / 3.0, -1.0 / 3.0, -1.0 / 3.0])
TRIAXIAL_DIRECTION_MANDEL = np.array([2.0 / 3.0, -1.0 / 3.0, -1.0 / 3.0, 0.0, 0.0, 0.0])

_ROWS = np.array([0, 1, 2, 1, 0, 0])
_COLS = np.array([0, 1, 2, 2, 2, 1])
_WEIGHTS = np.array([1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2])


def to_mandel(tensor: np.ndarray) -> np.ndarray:
    """Mandel vector ``(..., 6)`` of a symmetric tensor ``(..., 3, 3)``."""
    tensor = np.asarray(tensor, dtype=float)
    sym = 0.5 * (tensor + np.swapaxes(tensor, -1, -2))
    return sym[..., _ROWS, _COLS] * _WEIGHTS


def from_mandel(vector: np.ndarray) -> np.ndarray:
    """Symmetric tensor ``(..., 3, 3)`` of a Mandel vector ``(..., 6)``."""
    vector = np.asarray(vector, dtype=float)
    out = np.empty(vector.shape[:-1] + (3, 3))
    comps = vector / _WEIGHTS
    out[..., _ROWS, _COLS] = comps
    out[..., _COLS, _ROWS] = comps
    return out


#: The six orthonormal basis tensors of the Mandel representation, shape (6, 3, 3).
MANDEL_BASIS = from_mandel(np.eye(6))


def mandel_to_tensor4(matrix: np.ndarray) -> np.ndarray:
    """Fourth-order tensor ``(..., 3, 3, 3, 3)`` of a Mandel matrix ``(..., 6, 6)``."""
    return np.einsum("...ab,aij,bkl->...ijkl", matrix, MANDEL_BASIS, MANDEL_BASIS)


def tensor4_to_mandel(tensor: np.ndarray) -> np.ndarray:
    """Mandel matrix ``(..., 6, 6)`` of a fourth-order tensor with minor symmetries."""
    return np.einsum("...ijkl,aij,bkl->...ab", tensor, MANDEL_BASIS, MANDEL_BASIS)


def trace(m: np.ndarray) -> np.ndarray:
    """Trace of Mandel vectors (first three components summed)."""
    return m[..., 0] + m[..., 1] + m[..., 2]


def deviator(m: np.ndarray) -> np.ndarray:
    """Deviatoric part of Mandel vectors."""
    out = np.array(m, dtype=float, copy=True)
    out[..., :3] -= trace(m)[..., None] / 3.0
    return out


def mean_stress(sigma_m: np.ndarray) -> np.ndarray:
    """p = tr σ / 3 of a Mandel stress (kPa)."""
    return trace(sigma_m) / 3.0


def deviatoric_invariant(m: np.ndarray) -> np.ndarray:
    """sqrt(3/2 dev:dev): q for a stress, β_s for a (deviatoric) fabric tensor."""
    d = deviator(m)
    return np.sqrt(1.5 * np.sum(d * d, axis=-1))


def deviatoric_strain_invariant(m: np.ndarray) -> np.ndarray:
    """ε_s = sqrt(2/3 e:e) of a Mandel strain."""
    d = deviator(m)
    return np.sqrt(np.sum(d * d, axis=-1) / 1.5)


def triaxial(axial: float, radial: float) -> np.ndarray:
    """Mandel vector of diag(axial, radial, radial)."""
    return np.array([axial, radial, radial, 0.0, 0.0, 0.0])


def triaxial_fabric(beta: float) -> np.ndarray:
    """Mandel vector of the triaxial fabric β diag(2/3, −1/3, −1/3) (β signed like q)."""
    return beta * TRIAXIAL_DIRECTION_MANDEL


def axial_minus_radial(m: np.ndarray) -> np.ndarray:
    """m_11 − m_22 (axial minus radial): q for a stress, the signed scalar β for a fabric."""
    return m[..., 0] - m[..., 1]


def symmetric_product_matrix(beta_m: np.ndarray) -> np.ndarray:
    """Mandel matrix ``(..., 6, 6)`` of the linear map ε ↦ sym(β·ε) (symmetric in Mandel form)."""
    beta = from_mandel(beta_m)
    prod = np.einsum("...ik,jkl->...jil", beta, MANDEL_BASIS)
    cols = to_mandel(prod)  # (..., 6 [column j], 6 [row])
    return np.swapaxes(cols, -1, -2)
