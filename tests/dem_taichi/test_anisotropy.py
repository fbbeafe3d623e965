"""Interaction fabrics and affine stiffness of a network against hand values."""

import numpy as np
import pytest

from dem_taichi.response.anisotropy import network_anisotropy
from dem_taichi.response.linear import NetworkSnapshot

K_N = 1.0e3


def stacked_rods(gap: float, charge=(0, 0, 0), lateral: float = 0.0) -> NetworkSnapshot:
    """Two horizontal 3-disc rods, rod 1 at (lateral, gap) from rod 0; pairs i–i listed."""
    cell = 40.0
    centre = np.array([cell / 2, cell / 2])
    return NetworkSnapshot(
        cell_lengths=[cell, cell],
        rod_position=[centre, centre + [lateral, gap]],
        rod_angle=[0.0, 0.0],
        n_spheres=3,
        spacing=1.0,
        diameter=1.0,
        disc_mass=1.0,
        charge=list(charge),
        f_max=[10.0, 10.0, 10.0],
        k_a=[20.0, 20.0, 20.0],
        k_n=K_N,
        k_t=0.0,
        mu=0.5,
        vdw_f_max=0.0,
        vdw_k=0.0,
        pair_i=[0, 1, 2],
        pair_j=[3, 4, 5],
        pair_shift=np.zeros((3, 2)),
        tangential_spring=np.zeros((3, 2)),
        sliding=[False, False, False],
    )


def test_rods_lying_stacked_stiffen_only_the_vertical():
    """Rods lying down (β_yy − β_xx = −1) touching face to face: every contact normal is
    vertical (φ_yy − φ_xx = +1) and the affine contact stiffness has no horizontal part."""
    a = network_anisotropy(stacked_rods(0.95))
    assert a.rod_fabric_deviator == pytest.approx(-1.0)
    assert a.n_contacts == 3 and a.n_long_range == 0
    assert a.contact_normal_deviator == pytest.approx(1.0)
    assert a.contact_force_weighted_deviator == pytest.approx(1.0)
    assert a.affine_e_v_contact == pytest.approx(3 * K_N * 0.95**2 / 40.0**2)
    assert a.affine_e_h_contact == pytest.approx(0.0, abs=1e-12)
    assert a.affine_ratio_contact == pytest.approx(0.0, abs=1e-12)
    assert np.isnan(a.long_range_normal_deviator)


def test_oblique_long_range_pairs_split_by_direction():
    """Charged rods out of contact: the pairs are long-range only; with a lateral offset their
    normals are oblique, and C_xx/C_yy = (n_x l_x)²/(n_y l_y)² summed over the pairs."""
    snap = stacked_rods(1.2, charge=(1, 1, 1), lateral=0.3)
    a = network_anisotropy(snap)
    assert a.n_contacts == 0 and a.n_long_range == 3
    r = np.array([-0.3, -1.2])  # x_i - x_j for every listed pair
    n = r / np.linalg.norm(r)
    assert a.long_range_normal_deviator == pytest.approx(n[1] ** 2 - n[0] ** 2)
    assert a.affine_ratio == pytest.approx((n[0] * 0.3) ** 2 / (n[1] * 1.2) ** 2)
    assert a.contact_share_v == pytest.approx(0.0)


# ---- the command line's output file (issue 22) -----------------------------------------------


@pytest.fixture(scope="module")
def state_folder(tmp_path_factory):
    """A folder with one labelled state (the smoke scene's gas, saved as state_A.npz)."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.scene.config import load_scene

    folder = tmp_path_factory.mktemp("anisotropy")
    Simulation(load_scene("smoke")).save_checkpoint(folder / "state_A.npz")
    return folder


def _one_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def test_an_existing_table_is_refused_unless_overwrite(state_folder, capsys):
    import json

    from dem_taichi.response.anisotropy import main

    target = state_folder / "anisotropy.json"
    target.unlink(missing_ok=True)
    assert main([str(state_folder), "--quiet"]) == 0
    assert json.loads(target.read_text())[0]["state"] == "A"
    target.write_text("the user's edits")
    capsys.readouterr()
    assert main([str(state_folder)]) == 2
    line = _one_line(capsys.readouterr().err)
    assert str(target) in line and "--overwrite" in line
    assert target.read_text() == "the user's edits"
    assert main([str(state_folder), "--overwrite"]) == 0
    assert json.loads(target.read_text())[0]["state"] == "A"
    assert not [p for p in state_folder.iterdir() if p.name.startswith(".")]  # no temporary


def test_a_link_as_the_table_is_refused_and_replaced_never_written_through(
    state_folder, tmp_path, capsys
):
    from dem_taichi.response.anisotropy import main

    precious = tmp_path / "precious.json"
    precious.write_text("keep me")
    target = state_folder / "anisotropy.json"
    target.unlink(missing_ok=True)
    target.symlink_to(precious)
    try:
        assert main([str(state_folder)]) == 2
        assert "--overwrite" in _one_line(capsys.readouterr().err)
        assert target.is_symlink() and precious.read_text() == "keep me"
        assert main([str(state_folder), "--overwrite"]) == 0
        assert not target.is_symlink() and precious.read_text() == "keep me"
    finally:
        target.unlink(missing_ok=True)


def test_a_folder_without_states_is_one_line(tmp_path, capsys):
    from dem_taichi.response.anisotropy import main

    assert main([str(tmp_path)]) == 2
    assert "no state_*.npz" in _one_line(capsys.readouterr().err)
