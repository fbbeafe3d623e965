"""ParaView snapshots (dem_taichi.io.vtk_snapshots): read back by meshio, values those of the
simulation, rigid and bonded rods; the .pvd lists the files."""

from __future__ import annotations

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

from dem_taichi.io.stages import stage_code  # noqa: E402
from dem_taichi.io.vtk_snapshots import (  # noqa: E402
    POINT_FIELDS,
    read_pvd,
    write_pvd,
    write_simulation_snapshot,
)
from dem_taichi.scene.config import load_scene  # noqa: E402


def _simulation(rod_model: str):
    from dem_taichi.engine.simulation import Simulation

    scene = load_scene("smoke")
    if rod_model != scene.particles.rod_model:
        scene = scene.replace(particles={"rod_model": rod_model})
    sim = Simulation(scene)
    sim.run(200, output_every=10**9)
    return sim


@pytest.mark.parametrize("rod_model", ["rigid", "bonded"])
def test_snapshot_read_by_meshio_carries_the_simulation(rod_model, tmp_path):
    sim = _simulation(rod_model)
    path = write_simulation_snapshot(
        tmp_path / "paraview" / "state_A.vtu", sim, "A_to_B", fields={"mean_stress": 1.25}
    )
    mesh = meshio.read(path)
    n_s, n_rods = sim.geometry.n_spheres, sim.n_rods
    m = n_rods * n_s
    discs = sim.disc_positions()
    assert mesh.points.shape == (m, 3)
    np.testing.assert_array_equal(mesh.points[:, :2], discs)
    assert np.all(mesh.points[:, 2] == 0.0)
    assert mesh.cells[0].type == "vertex" and mesh.cells[0].data.shape == (m, 1)
    data = mesh.point_data
    assert set(POINT_FIELDS) <= set(data)
    r = np.arange(m) // n_s
    s = np.arange(m) % n_s
    np.testing.assert_array_equal(data["rod_id"], r)
    np.testing.assert_array_equal(data["disc_index"], s)
    np.testing.assert_array_equal(data["angle"], sim.rod_angles()[r])
    np.testing.assert_array_equal(data["charge"], sim.charge[s])
    np.testing.assert_array_equal(data["diameter"], sim.geometry.diameter)
    np.testing.assert_array_equal(data["radius"], 0.5 * sim.geometry.diameter)
    state = sim.get_state()
    body = np.arange(m) if sim.bonded else r
    np.testing.assert_array_equal(data["body_id"], body)
    np.testing.assert_array_equal(data["body_force"][:, :2], state["force"][body])
    assert np.all(data["body_force"][:, 2] == 0.0)
    np.testing.assert_array_equal(data["body_torque"], state["torque"][body])
    assert np.any(state["force"] != 0.0)
    # every disc of a rigid rod sits on its axis: the angle is the rod's
    if not sim.bonded:
        d = discs[n_s - 1 :: n_s] - discs[0::n_s]
        np.testing.assert_allclose(np.arctan2(d[:, 1], d[:, 0]), sim.rod_angles(), atol=1e-9)
    field = mesh.field_data
    assert int(field["stage_code"].ravel()[0]) == stage_code("A_to_B")
    assert int(field["step"].ravel()[0]) == sim.step
    assert float(field["time"].ravel()[0]) == sim.time
    np.testing.assert_array_equal(field["cell_lengths"].ravel(), sim.cell_lengths)
    assert float(field["mean_stress"].ravel()[0]) == 1.25


def test_pvd_lists_the_snapshots_in_order(tmp_path):
    sim = _simulation("rigid")
    folder = tmp_path / "paraview"
    files = [
        (label, write_simulation_snapshot(folder / f"state_{k}.vtu", sim, "A_to_B"))
        for k, label in enumerate(["A", "B", "B'"])
    ]
    pvd = write_pvd(folder / "states.pvd", files)
    text = pvd.read_text()
    assert 'type="Collection"' in text and 'file="state_0.vtu"' in text
    entries = read_pvd(pvd)
    assert [name for name, _ in entries] == ["A", "B", "B'"]
    assert [p.resolve() for _, p in entries] == [p.resolve() for _, p in files]
    for _, p in entries:
        assert meshio.read(p).points.shape[0] == sim.n_discs


def test_bad_inputs_refused(tmp_path):
    sim = _simulation("rigid")
    with pytest.raises(ValueError, match="ends in .vtu"):
        write_simulation_snapshot(tmp_path / "a.vtk", sim, "A_to_B")
    with pytest.raises(ValueError, match="unknown stage"):
        write_simulation_snapshot(tmp_path / "a.vtu", sim, "nowhere")


def test_run_writes_paraview_series_and_snapshot_command_converts_a_state(tmp_path, capsys):
    """``run --paraview`` writes a snapshot at every checkpoint and at the end, listed in
    ``run.pvd``; ``snapshot STATE.npz --out F.vtu`` writes the discs of a saved state (on
    request), equal to the run's own snapshot of that step; bad arguments are one line."""
    from dem_taichi.cli.commands import main

    out = tmp_path / "run"
    assert (
        main(["run", "smoke", "--out", str(out), "--steps", "6000", "--paraview", "--quiet"]) == 0
    )
    series = read_pvd(out / "paraview" / "run.pvd")
    steps = [name for name, _ in series]
    assert steps == ["step 5000", "step 6000"]
    checkpoint = sorted((out / "checkpoints").glob("checkpoint_*.npz"))[-1]
    target = tmp_path / "state.vtu"
    assert main(["snapshot", str(checkpoint), "--out", str(target), "--quiet"]) == 0
    mine, theirs = meshio.read(target), meshio.read(series[-1][1])
    np.testing.assert_array_equal(mine.points, theirs.points)
    for name in ("rod_id", "angle", "charge", "body_force"):
        np.testing.assert_array_equal(mine.point_data[name], theirs.point_data[name])
    capsys.readouterr()
    assert main(["snapshot", str(tmp_path / "none.npz"), "--out", str(target)]) == 2
    assert main(["snapshot", str(checkpoint), "--out", str(tmp_path / "x.png")]) == 2
    err = capsys.readouterr().err
    assert "no such file" in err and "ending .vtu" in err and "Traceback" not in err
