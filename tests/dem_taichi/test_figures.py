"""DEM figures render from datasets with the schema names; disc geometry is exact."""

import numpy as np
import xarray as xr

from dem_taichi.analysis.figures import figure_paths, figure_states, stage_labels
from dem_taichi.physics.forcelaw import disc_positions


def test_disc_centres_follow_the_rod_axis():
    centres = disc_positions(np.array([[1.0, 2.0]]), np.array([np.pi / 2]), 5, 1.0)
    np.testing.assert_allclose(centres[:, 0], 1.0, atol=1e-12)
    np.testing.assert_allclose(centres[:, 1], [0.0, 1.0, 2.0, 3.0, 4.0], atol=1e-12)


def make_history(n=40):
    stage = np.repeat([1, 2, 3], [10, 15, 15]).astype(np.int8)
    p = np.linspace(0.01, 1.0, n)
    ds = xr.Dataset(
        {
            "stage": (
                "time",
                stage,
                {
                    "flag_values": np.array([1, 2, 3], np.int8),
                    "flag_meanings": "isotropic_to_A A_to_B A_to_C",
                },
            ),
            "mean_stress": ("time", p),
            "deviatoric_stress": ("time", np.where(stage == 3, 0.5 * p, 0.0)),
            "specific_volume": ("time", 2.0 - 0.1 * np.log(p)),
            "fabric_deviator": ("time", np.where(stage == 3, -0.1 * p, 0.0)),
        }
    )
    return ds


def test_stage_labels_decode_flags():
    labels = stage_labels(make_history())
    assert labels[0] == "isotropic_to_A" and labels[-1] == "A_to_C"


def test_figures_render(tmp_path):
    rng = np.random.default_rng(0)
    conf = xr.Dataset(
        {
            "rod_position": (("rod", "xy"), rng.uniform(0, 10, (12, 2))),
            "rod_angle": ("rod", rng.uniform(0, np.pi, 12)),
            "cell_lengths": ("xy", [10.0, 10.0]),
            "mean_stress": 0.5,
            "deviatoric_stress": 0.1,
        }
    )
    geometry = {"n_spheres": 5, "spacing": 1.0, "diameter": 1.0}
    out = figure_paths(make_history(), {"A": conf, "C": conf}, tmp_path / "f1.png", geometry)
    assert out.stat().st_size > 10_000
    probes = xr.Dataset(
        {
            "mean_stress": ("probe", [0.1, 0.5]),
            "state_label": ("probe", ["A", "C"]),
            "e_oed_v_linear": ("probe", [10.0, 20.0]),
            "e_oed_h_linear": ("probe", [11.0, 30.0]),
            "e_oed_v_dynamic": ("probe", [10.2, 19.5]),
            "e_oed_h_dynamic": ("probe", [np.nan, 29.0]),
        }
    )
    out = figure_states(make_history(), probes, tmp_path / "f2.png")
    assert out.stat().st_size > 10_000
    assert figure_states(make_history(), None, tmp_path / "f3.png").exists()
