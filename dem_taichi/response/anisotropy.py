"""Where the stiffness anisotropy of a rod network comes from: fabrics of the interactions and
the affine (Born) stiffness split by interaction type and direction (numpy; no Taichi import
except in :func:`main`, which reads checkpoints).

Why: the study links E_oed,h/E_oed,v > 1 to rods lying down (rod-orientation fabric
β_yy − β_xx < 0). A rigid rod transmits force only through its interactions, so what the
stiffness sees is the fabric of the interaction normals n (disc–disc direction) and branch
vectors l (centroid–centroid), weighted by the pair stiffness k_N. This module measures those,
so that a DEM result can be read: e.g. rods lying down and stacked make contact normals
vertical, which stiffens the vertical direction, not the horizontal one.

Definitions (DEM units; pairs as in :class:`dem_taichi.physics.snapshot.NetworkSnapshot`):

- rod fabric β = (1/N) Σ a ⊗ a (study Eq. 1), deviator β_yy − β_xx;
- interaction-normal fabric φ = ⟨n ⊗ n⟩ over a set of pairs, deviator φ_yy − φ_xx ∈ [−1, 1];
- affine normal-spring stiffness (Born term of the normal springs, no relaxation, no pre-stress
  or tangential terms): under a compression-positive strain ε_yy with rods translated affinely
  and not rotated, dN = k_N n_y l_y ε_yy and dσ_yy = (1/A) Σ dN n_y l_y, so
  C_yy = (1/A) Σ k_N n_y² l_y² and C_xx = (1/A) Σ k_N n_x² l_x²; these are upper bounds of the
  normal-spring part of E_oed,v and E_oed,h (relaxation only lowers them).
"""

from __future__ import annotations

import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from dem_taichi.analysis.arrays import fabric_tensor
from dem_taichi.physics import forcelaw

__all__ = ["NetworkAnisotropy", "network_anisotropy", "main"]


@dataclass(frozen=True)
class NetworkAnisotropy:
    """Directional make-up of one network (see the module docstring for the definitions).

    ``*_contact`` over pairs in contact (overlap > 0), ``*_long_range`` over the other pairs that
    carry a long-range force; stiffness entries in force/length² (DEM stress units).
    """

    rod_fabric_deviator: float
    n_contacts: int
    n_long_range: int
    contact_normal_deviator: float
    long_range_normal_deviator: float
    contact_force_weighted_deviator: float
    affine_e_v_contact: float
    affine_e_h_contact: float
    affine_e_v_long_range: float
    affine_e_h_long_range: float

    @property
    def affine_ratio_contact(self) -> float:
        """C_xx/C_yy of the contact springs (E_h/E_v they alone would give, affinely)."""
        return _ratio(self.affine_e_h_contact, self.affine_e_v_contact)

    @property
    def affine_ratio(self) -> float:
        """C_xx/C_yy of all normal springs, affine."""
        return _ratio(
            self.affine_e_h_contact + self.affine_e_h_long_range,
            self.affine_e_v_contact + self.affine_e_v_long_range,
        )

    @property
    def contact_share_v(self) -> float:
        """Share of the contacts in the affine vertical stiffness C_yy."""
        return _ratio(self.affine_e_v_contact, self.affine_e_v_contact + self.affine_e_v_long_range)


def _ratio(a: float, b: float) -> float:
    return float(a / b) if b > 0 else float("nan")


def _normal_deviator(normal: np.ndarray, weight: np.ndarray | None = None) -> float:
    if normal.shape[0] == 0:
        return float("nan")
    w = np.ones(normal.shape[0]) if weight is None else np.asarray(weight, dtype=float)
    if not np.sum(w) > 0:
        return float("nan")
    return float(np.sum(w * (normal[:, 1] ** 2 - normal[:, 0] ** 2)) / np.sum(w))


def network_anisotropy(snapshot) -> NetworkAnisotropy:
    """Fabrics and affine normal-spring stiffness of a :class:`NetworkSnapshot`."""
    pairs = forcelaw.pair_forces(snapshot)
    n, branch = pairs.normal, pairs.branch
    contact = np.asarray(pairs.in_contact, dtype=bool)
    long_range = ~contact & (np.abs(pairs.long_range_force) > 0)
    area = float(np.prod(snapshot.cell_lengths))
    k_contact = np.where(contact, forcelaw.contact_normal_stiffness(pairs.overlap, snapshot.k_n), 0)
    k_long = np.where(long_range, pairs.normal_stiffness, 0.0)

    def affine(k: np.ndarray, axis: int) -> float:
        return float(np.sum(k * (n[:, axis] * branch[:, axis]) ** 2) / area)

    beta = fabric_tensor(snapshot.rod_angle)
    return NetworkAnisotropy(
        rod_fabric_deviator=float(beta[1, 1] - beta[0, 0]),
        n_contacts=int(contact.sum()),
        n_long_range=int(long_range.sum()),
        contact_normal_deviator=_normal_deviator(n[contact]),
        long_range_normal_deviator=_normal_deviator(n[long_range]),
        contact_force_weighted_deviator=_normal_deviator(
            n[contact], np.maximum(pairs.normal_force[contact], 0.0)
        ),
        affine_e_v_contact=affine(k_contact, 1),
        affine_e_h_contact=affine(k_contact, 0),
        affine_e_v_long_range=affine(k_long, 1),
        affine_e_h_long_range=affine(k_long, 0),
    )


def _row(label: str, a: NetworkAnisotropy) -> dict:
    row = {"state": label, **asdict(a)}
    row.update(
        affine_ratio_contact=a.affine_ratio_contact,
        affine_ratio=a.affine_ratio,
        contact_share_v=a.contact_share_v,
    )
    return row


PROG = "python -m dem_taichi anisotropy"
OUTPUT = "anisotropy.json"


def _parser(prog: str = PROG):
    from clay_cli import ArgumentParser, add_common_flags

    parser = ArgumentParser(
        prog=prog,
        description="Fabrics and affine stiffness of the interaction network at the labelled "
        f"states (state_*.npz) of a protocol run; writes {OUTPUT} beside them.",
    )
    parser.add_argument("run_dir", help="output folder of python -m dem_taichi protocol")
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help=f"replace an existing RUN_DIR/{OUTPUT} (else refused)",
    )
    add_common_flags(parser)
    return parser


def _table(argv: list[str], prog: str = PROG) -> int:
    from clay_cli import UsageError, refuse_control_characters, replace_file

    refuse_control_characters(argv)
    args = _parser(prog).parse_args(argv)
    folder = Path(args.run_dir)
    if not folder.is_dir():
        raise UsageError(f"{folder}: no such folder; give the output folder of a protocol run")
    order = {"A": 0, "B": 1, "C": 2, "B_prime": 3}
    paths = sorted(folder.glob("state_*.npz"), key=lambda p: order.get(p.stem[6:], 9))
    if not paths:
        raise UsageError(f"no state_*.npz in {folder}; give the output folder of a protocol run")
    target = folder / OUTPUT
    if target.is_dir() and not target.is_symlink():
        raise UsageError(f"{target} is a folder; move it away to write the table")
    if (target.exists() or target.is_symlink()) and not args.overwrite:
        raise UsageError(
            f"{target} exists; add --overwrite to replace it (a link is replaced, never its "
            "target), or move it away"
        )
    from dem_taichi.engine.simulation import Simulation

    rows = []
    for path in paths:
        label = path.stem[6:].replace("_prime", "'")
        rows.append(_row(label, network_anisotropy(Simulation.from_checkpoint(path).snapshot())))
    head = ("state", "rod β dev", "contact n dev", "force-weighted n dev", "LR n dev",
            "contacts", "LR pairs", "affine Eh/Ev contact", "affine Eh/Ev all",
            "contact share Ev")  # fmt: skip
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print(
            f"| {r['state']} | {r['rod_fabric_deviator']:+.3f} | "
            f"{r['contact_normal_deviator']:+.3f} | {r['contact_force_weighted_deviator']:+.3f} | "
            f"{r['long_range_normal_deviator']:+.3f} | {r['n_contacts']} | {r['n_long_range']} | "
            f"{r['affine_ratio_contact']:.3f} | {r['affine_ratio']:.3f} | "
            f"{r['contact_share_v']:.3f} |"
        )
    replace_file(target, lambda temporary: temporary.write_text(json.dumps(rows, indent=2)))
    return 0


def main(argv: list[str] | None = None, prog: str = PROG) -> int:
    """``python -m dem_taichi anisotropy RUN_DIR [--overwrite]``: table of the labelled
    states' checkpoints, written to ``RUN_DIR/anisotropy.json`` (atomically; an existing file, or a
    link there, is refused unless ``--overwrite``, which replaces the link, never its target).
    Errors are one line, exit code 2 (:func:`clay_cli.run_command`)."""
    from clay_cli import run_command
    from dem_taichi.io import CheckpointError

    return run_command(prog, lambda args: _table(args, prog), argv, user_errors=(CheckpointError,))


if __name__ == "__main__":
    sys.exit(main())
