"""Disc-level snapshots for ParaView: one VTK file per state and a ``.pvd`` time series.

numpy only (``meshio`` is imported when a file is written; no Taichi). A snapshot is an
unstructured grid of ``vertex`` cells, one point per disc at (x, y, 0) — meshio writes VTK XML
unstructured grids (``.vtu``), not PolyData (``.vtp``); ParaView shows both the same way. The
discs are rod-major (global disc index r·n_s + s) and their positions are the engine's, not
wrapped into the cell.

Point data (``POINT_FIELDS``): ``rod_id`` r, ``disc_index`` s, ``body_id`` (the rod for rigid
rods, the disc for bonded rods), ``angle`` θ of the rod (rad), ``charge`` c_s, ``diameter`` and
``radius`` of the disc, ``body_force`` (x, y, 0) and ``body_torque`` of the body the disc belongs
to (for rigid rods the rod's force and torque, repeated on each of its discs). Field data (global,
one tuple): ``stage_code`` (:data:`dem_taichi.io.schema.STAGE_CODES`), ``step``, ``time``,
``cell_lengths`` (L_x, L_y) and any further numbers given (``mean_stress`` …). meshio's writer
drops field data, so it is added to the file afterwards (ASCII ``<FieldData>``, read back by
``meshio.read`` as ``mesh.field_data`` and by ParaView as field data).

Typical use: ``snap = simulation_snapshot(sim)`` when a state is reached, later
``write_snapshot(path, **snap, stage="A_to_B")``, and ``write_pvd(dir / "states.pvd", files)``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from dem_taichi.io.stages import stage_code

POINT_FIELDS = (
    "rod_id", "disc_index", "body_id", "angle", "charge", "diameter", "radius", "body_force",
    "body_torque",
)  # fmt: skip


def disc_point_data(
    disc_positions: np.ndarray,
    rod_angles: np.ndarray,
    charge: np.ndarray,
    diameter: float,
    force: np.ndarray,
    torque: np.ndarray,
    bonded: bool,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The points (M, 3) and the point data of ``POINT_FIELDS`` for M = N·n_s discs.

    ``charge`` is per place in a rod (n_s,); ``force`` (n_bodies, 2) and ``torque``
    (n_bodies,) are the bodies' (N rods, or the M discs of bonded rods)."""
    xy = np.asarray(disc_positions, dtype=np.float64)
    angles = np.asarray(rod_angles, dtype=np.float64)
    charge = np.asarray(charge)
    n_rods, n_s = angles.shape[0], charge.shape[0]
    m = n_rods * n_s
    if xy.shape != (m, 2):
        raise ValueError(f"disc positions of shape {xy.shape}: expected ({m}, 2)")
    n_bodies = m if bonded else n_rods
    force = np.asarray(force, dtype=np.float64)
    torque = np.asarray(torque, dtype=np.float64)
    if force.shape != (n_bodies, 2) or torque.shape != (n_bodies,):
        raise ValueError(
            f"force {force.shape} and torque {torque.shape}: expected ({n_bodies}, 2) and "
            f"({n_bodies},) for {'bonded' if bonded else 'rigid'} rods"
        )
    rod_id = np.repeat(np.arange(n_rods, dtype=np.int32), n_s)
    body_id = np.arange(m, dtype=np.int32) if bonded else rod_id
    force3 = np.zeros((n_bodies, 3))
    force3[:, :2] = force
    points = np.zeros((m, 3))
    points[:, :2] = xy
    data = {
        "rod_id": rod_id,
        "disc_index": np.tile(np.arange(n_s, dtype=np.int32), n_rods),
        "body_id": body_id,
        "angle": np.repeat(angles, n_s),
        "charge": np.tile(charge.astype(np.int32), n_rods),
        "diameter": np.full(m, float(diameter)),
        "radius": np.full(m, 0.5 * float(diameter)),
        "body_force": force3[body_id],
        "body_torque": torque[body_id],
    }
    return points, data


def simulation_snapshot(sim) -> dict:
    """What :func:`write_snapshot` needs, read from a
    :class:`dem_taichi.engine.simulation.Simulation` now (copies; call it when the state is
    reached)."""
    state = sim.get_state()
    return {
        "disc_positions": sim.disc_positions(),
        "rod_angles": sim.rod_angles(),
        "charge": np.asarray(sim.charge).copy(),
        "diameter": float(sim.geometry.diameter),
        "force": np.asarray(state["force"], dtype=np.float64),
        "torque": np.asarray(state["torque"], dtype=np.float64),
        "bonded": bool(sim.bonded),
        "cell_lengths": np.asarray(sim.cell_lengths, dtype=np.float64),
        "step": int(sim.step),
        "time": float(sim.time),
    }


def write_snapshot(
    path: str | Path,
    disc_positions: np.ndarray,
    rod_angles: np.ndarray,
    charge: np.ndarray,
    diameter: float,
    force: np.ndarray,
    torque: np.ndarray,
    bonded: bool,
    cell_lengths: np.ndarray,
    stage: str,
    step: int = 0,
    time: float = 0.0,
    fields: Mapping[str, float] | None = None,
) -> Path:
    """Write one snapshot (``.vtu``) at ``path``; see the module docstring for its contents.

    ``stage`` is a stage label (``"A_to_B"`` …), stored as its code; ``fields`` adds numbers to
    the field data."""
    import meshio

    path = Path(path)
    if path.suffix != ".vtu":
        raise ValueError(f"{path}: a snapshot file ends in .vtu")
    points, data = disc_point_data(
        disc_positions, rod_angles, charge, diameter, force, torque, bonded
    )
    cells = [("vertex", np.arange(points.shape[0], dtype=np.int64)[:, None])]
    path.parent.mkdir(parents=True, exist_ok=True)
    meshio.Mesh(points, cells, point_data=data).write(path, file_format="vtu")
    field_data: dict[str, np.ndarray] = {
        "stage_code": np.array([stage_code(stage)], dtype=np.int32),
        "step": np.array([int(step)], dtype=np.int64),
        "time": np.array([float(time)]),
        "cell_lengths": np.asarray(cell_lengths, dtype=np.float64).reshape(1, 2),
    }
    for name, value in (fields or {}).items():
        field_data[name] = np.array([float(value)])
    _add_field_data(path, field_data)
    return path


def write_simulation_snapshot(
    path: str | Path, sim, stage: str, fields: Mapping[str, float] | None = None
) -> Path:
    """Write the snapshot of a :class:`dem_taichi.engine.simulation.Simulation` as it is now."""
    return write_snapshot(path, **simulation_snapshot(sim), stage=stage, fields=fields)


_VTK_TYPES = {"i": {4: "Int32", 8: "Int64"}, "f": {8: "Float64"}}


def _add_field_data(path: Path, field_data: Mapping[str, np.ndarray]) -> None:
    tree = ET.parse(path)
    grid = tree.getroot().find("UnstructuredGrid")
    if grid is None:  # meshio writes one
        raise ValueError(f"{path}: no UnstructuredGrid element")
    block = ET.Element("FieldData")
    for name, values in field_data.items():
        values = np.atleast_2d(values)
        array = ET.SubElement(
            block,
            "DataArray",
            type=_VTK_TYPES[values.dtype.kind][values.dtype.itemsize],
            Name=name,
            NumberOfTuples=str(values.shape[0]),
            format="ascii",
        )
        if values.shape[1] > 1:
            array.set("NumberOfComponents", str(values.shape[1]))
        array.text = " ".join(repr(v.item()) for v in values.ravel())
    grid.insert(0, block)
    tree.write(path, xml_declaration=True, encoding="utf-8")


def write_pvd(path: str | Path, files: Sequence[tuple[str, str | Path]]) -> Path:
    """Write a ParaView collection ``path`` listing ``files`` as (name, snapshot path) in order:
    time step k is the k-th file (the states of different branches share no time axis); the
    paths are written relative to the ``.pvd``'s folder."""
    path = Path(path)
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for k, (name, file) in enumerate(files):
        relative = Path(file).resolve().relative_to(path.parent.resolve())
        ET.SubElement(
            collection,
            "DataSet",
            timestep=str(k),
            group="",
            part="0",
            name=str(name),
            file=relative.as_posix(),
        )
    ET.indent(root)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, xml_declaration=True, encoding="utf-8")
    return path


def read_pvd(path: str | Path) -> list[tuple[str, Path]]:
    """The (name, absolute file path) entries of a ``.pvd`` written by :func:`write_pvd`."""
    path = Path(path)
    entries = ET.parse(path).getroot().find("Collection")
    if entries is None:
        raise ValueError(f"{path}: not a ParaView collection (no Collection element)")
    listed = []
    for entry in entries:
        file = entry.get("file")
        if file is None:
            raise ValueError(f"{path}: a DataSet without a file")
        listed.append((entry.get("name", ""), path.parent / file))
    return listed
