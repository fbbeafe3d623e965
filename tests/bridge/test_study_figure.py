"""The study's Figure 2 over replicas (bridge.study_figure): the bands, the study's curves, the
files and the command line, on synthetic replicas (the model with DEM-like noise, each run with
its own stress scale)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr
from matplotlib.container import ErrorbarContainer
from scipy import stats

from bridge.__main__ import main
from bridge.replica_bands import mean_and_half_width, path_members, record_labels, summary_labels
from bridge.replicas import history_stage
from bridge.series import Convention, SeriesError
from bridge.study_figure import (
    figure2,
    figure2_markdown,
    replica_bands,
    study_curves,
    write_study_figure,
)
from bridge.synthetic import DEM_NOISE, synthetic_results
from tiv_model import drivers
from tiv_model.integrate import Control, initial_state
from tiv_model.params import DEFAULT_OPTIONS, TABLE1

from .conftest import TRUTH

#: Each replica's stress scale (kPa per DEM unit): the bands must use each run's own.
SCALES = (1.0, 2.0, 0.5)


def replica(folder, seed, scale=1.0, increments=4):
    """A synthetic protocol run folder: isotropic, K0, unloading and one radial path (η 0.4)."""
    syn = synthetic_results(
        TRUTH,
        convention=Convention(scale),
        increments=increments,
        unloading_increments=2,
        noise=DEM_NOISE,
        seed=seed,
        radial_ratios=(0.4,),
    )
    folder.mkdir(parents=True)
    syn.history.to_netcdf(folder / "relaxed_states.nc")
    syn.probes.to_netcdf(folder / "probes.nc")
    return folder


@pytest.fixture(scope="module")
def replicas(tmp_path_factory):
    root = tmp_path_factory.mktemp("figure2")
    return [replica(root / f"seed-{k}", k, s) for k, s in enumerate(SCALES, start=1)]


@pytest.fixture(scope="module")
def bands(replicas):
    return replica_bands(replicas)


@pytest.fixture(scope="module")
def curves(bands):
    return study_curves(bands, TABLE1, k0_mode="stress", substeps=1)


def interval(x):
    """Mean and 95 % half-width over axis 0, through scipy's t interval of the mean."""
    mean = x.mean(axis=0)
    low, high = stats.t.interval(0.95, x.shape[0] - 1, loc=mean, scale=stats.sem(x, axis=0))
    return mean, (high - low) / 2.0


def test_bands_are_the_mean_and_t_interval_of_each_runs_values_in_kpa(replicas, bands):
    history = [xr.load_dataset(r / "relaxed_states.nc") for r in replicas]
    probes = [xr.load_dataset(r / "probes.nc") for r in replicas]
    scale = [ds.attrs["stress_scale_kpa"] for ds in history]
    assert scale == list(SCALES) and int(bands["n"]) == 3
    # every synthetic run has state A as its first record: the aligned records are all of them
    sa = np.stack([s * ds["stress_yy"].values for s, ds in zip(scale, history, strict=True)])
    sr = np.stack([s * ds["stress_xx"].values for s, ds in zip(scale, history, strict=True)])
    p = (sa + 2.0 * sr) / 3.0
    expected = {
        "mean_stress": p,
        "stress_ratio": (sa - sr) / p,
        "specific_volume": np.stack([ds["specific_volume"].values for ds in history]),
        "fabric": -np.stack([ds["fabric_deviator"].values for ds in history]),
    }
    ev = np.stack([s * ds["e_oed_v_linear"].values for s, ds in zip(scale, probes, strict=True)])
    eh = np.stack([s * ds["e_oed_h_linear"].values for s, ds in zip(scale, probes, strict=True)])
    p_probe = np.stack(
        [
            s * (ds["stress_yy"].values + 2.0 * ds["stress_xx"].values) / 3.0
            for s, ds in zip(scale, probes, strict=True)
        ]
    )
    expected |= {
        "probe_mean_stress": p_probe,
        "probe_e_oed_v": ev,
        "probe_e_oed_h": eh,
        "probe_stiffness_ratio": eh / ev,
        "probe_e_oed_v_over_p": ev / p_probe,
    }
    for name, x in expected.items():
        mean, half = interval(x)
        np.testing.assert_allclose(bands[name].values, mean, rtol=1e-12, err_msg=name)
        np.testing.assert_allclose(bands[name + "_ci95"].values, half, rtol=1e-10, err_msg=name)
    # E_h/E_v is each run's ratio averaged, not the ratio of the mean moduli
    assert not np.allclose(bands["probe_stiffness_ratio"].values, eh.mean(0) / ev.mean(0))
    labels = [x for x in bands["state_label"].values if x]
    assert labels == ["A", "B", "C", "B'", "R1_end"]
    assert list(bands["probe_state_label"].values) == list(probes[0]["state_label"].values)


def test_half_width_is_nan_with_one_replica():
    mean, half, n = mean_and_half_width(np.array([[1.0, 2.0, np.nan], [3.0, np.nan, np.nan]]))
    np.testing.assert_array_equal(n, [2, 1, 0])
    assert mean[0] == 2.0 and mean[1] == 2.0 and np.isnan(mean[2])
    assert half[0] == pytest.approx(stats.t.ppf(0.975, 1) * np.sqrt(2.0) / np.sqrt(2.0))
    assert np.isnan(half[1]) and np.isnan(half[2])


def _direct(start, controls):
    """The TIV model with Table 1 driven directly (tiv_model, not the bridge): the records."""
    states, _ = drivers.run_path(start, controls, TABLE1, DEFAULT_OPTIONS, on_error="raise")
    return [drivers.record(s, TABLE1, DEFAULT_OPTIONS) for s in states]


def _compare(curve: xr.Dataset, point: int, record: dict, what: str) -> None:
    for name in ("mean_stress", "specific_volume", "fabric", "e_oed_v", "e_oed_h"):
        value = float(curve[name].values[point])
        assert value == pytest.approx(record[name], rel=1e-9, abs=1e-12), f"{what} {name}"


def test_study_curves_are_the_table1_model_on_our_mean_paths(bands, curves):
    stage = bands["stage"].values.astype(str)
    label = bands["state_label"].values.astype(str)
    sa, sr = bands["axial_stress"].values, bands["radial_stress"].values
    p_a = float(bands["mean_stress"].values[label == "A"][0])
    start = initial_state(p_a, TABLE1, DEFAULT_OPTIONS)  # the study's NC state at our p_A
    assert float(curves["isotropic"]["specific_volume"][0]) == pytest.approx(
        start.specific_volume, rel=1e-12
    )
    p = bands["mean_stress"].values[stage == "A_to_B"]
    iso = _direct(start, [Control.triaxial(axial_stress=x, radial_stress=x) for x in p])
    _compare(curves["isotropic"], -1, iso[-1], "B")
    path = (stage == "A_to_C") | (stage == "C_to_B")
    k0 = _direct(
        start,
        [
            Control.triaxial(axial_stress=a, radial_stress=r)
            for a, r in zip(sa[path], sr[path], strict=True)
        ],
    )
    n_k0 = int(np.sum(stage == "A_to_C"))
    _compare(curves["k0"], -1, k0[n_k0], "C")
    _compare(curves["unloading"], 0, k0[n_k0], "C (unloading)")
    _compare(curves["unloading"], -1, k0[-1], "B'")
    # the model at our C has the same stresses as ours; its fabric and v are its own
    assert float(curves["k0"]["mean_stress"][-1]) == pytest.approx(
        float(bands["mean_stress"].values[label == "C"][0]), rel=1e-12
    )


def test_study_curves_element_mode_is_the_k0_element_test(bands):
    curves = study_curves(bands, TABLE1, k0_mode="element", substeps=1)
    stage = bands["stage"].values.astype(str)
    label = bands["state_label"].values.astype(str)
    start = initial_state(float(bands["mean_stress"].values[label == "A"][0]), TABLE1)
    targets = bands["axial_stress"].values[stage == "A_to_C"]
    k0 = _direct(
        start, [Control.triaxial(axial_stress=a, radial_strain_increment=0.0) for a in targets]
    )
    _compare(curves["k0"], -1, k0[-1], "C")
    refined = study_curves(bands, TABLE1, substeps=3)
    assert refined["k0"].sizes["point"] == 3 * (curves["k0"].sizes["point"] - 1) + 1


def test_figure_draws_the_bands_as_error_bars_and_the_curves_as_lines(bands, curves):
    fig = figure2(bands, curves)
    axes = fig.axes[:4]
    for ax in axes:
        assert any(isinstance(c, ErrorbarContainer) for c in ax.containers), ax.get_title()
        assert len(ax.get_lines()) >= len(curves), ax.get_title()
    # panel a, isotropic path: the bars are ± the 95 % half-widths of v at the mean p
    stage = bands["stage"].values.astype(str)
    iso = np.concatenate(
        [np.flatnonzero(bands["state_label"].values == "A"), np.flatnonzero(stage == "A_to_B")]
    )
    container = next(c for c in axes[0].containers if len(c[0].get_xdata()) == iso.size)
    np.testing.assert_allclose(container[0].get_xdata(), bands["mean_stress"].values[iso])
    heights = [seg[1, 1] - seg[0, 1] for seg in container[2][-1].get_segments()]
    np.testing.assert_allclose(heights, 2.0 * bands["specific_volume_ci95"].values[iso])
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert "DEM, mean ± 95 % over 3 replicas" in texts and "TIV, Table 1 (the study)" in texts


def test_write_study_figure_writes_the_figure_and_its_table(replicas, bands, tmp_path):
    path = write_study_figure(replicas, tmp_path / "out", substeps=2)
    assert path == tmp_path / "out" / "figure2_replicas.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 20_000
    table = (tmp_path / "out" / "figure2_replicas.md").read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(): line for line in table.splitlines() if line[:2] == "| "}
    assert {"A", "B", "C", "B′", "R1_end"} <= set(rows)
    curves = study_curves(bands, TABLE1, substeps=2)
    i = int(np.flatnonzero(bands["state_label"].values == "C")[0])
    cells = [c.strip() for c in rows["C"].split("|")[1:-1]]
    p, half = bands["mean_stress"].values[i], bands["mean_stress_ci95"].values[i]
    assert cells[1] == f"{p:.4g} ± {half:.2g}"
    assert cells[6] == f"{float(curves['k0']['fabric'][-1]):.4g}"  # β TIV at C
    assert "E_h/E_v DEM" in table and "over n = 3 replicas" in table


def test_the_bands_file_gives_the_table_s_numbers_unrounded(replicas, tmp_path):
    """``figure2_replicas.nc`` holds the bands with units; the DEM means read from it at each
    labelled state (:func:`state_means`) are the table's DEM cells before rounding, and
    ``benchmarks/tiv_anisotropy_sources.py`` reads the same states from either file."""
    from bridge.study_figure_panels import state_means
    from tests.scripts import load_script

    out = tmp_path / "out"
    write_study_figure(replicas, out, substeps=2)
    with xr.open_dataset(out / "figure2_replicas.nc") as saved:
        bands = saved.load()
    assert bands["mean_stress"].attrs["units"] == "kPa" and int(bands["n"]) == 3
    means = state_means(bands)
    table = (out / "figure2_replicas.md").read_text(encoding="utf-8")
    rows = {line.split("|")[1].strip(): line for line in table.splitlines() if line[:2] == "| "}
    assert {label.replace("'", "′") for label in means} == set(rows) - {"state"}
    for label, values in means.items():
        cells = [c.strip() for c in rows[label.replace("'", "′")].split("|")[1:-1]]
        for column, name in ((1, "mean_stress"), (3, "specific_volume"), (9, "stiffness_ratio")):
            shown = f"{values[name]:.4g}" if np.isfinite(values[name]) else "—"
            assert cells[column].split(" ± ")[0] == shown
    sources = load_script("benchmarks/tiv_anisotropy_sources.py")
    from_nc = sources._states(out / "figure2_replicas.nc")
    from_md = sources._states(out / "figure2_replicas.md")
    assert set(from_nc) == set(from_md)
    for label, values in from_nc.items():
        for key, value in values.items():
            assert value == pytest.approx(from_md[label][key], rel=1e-3, abs=1e-4, nan_ok=True)


def test_fewer_than_two_replicas_is_one_line(replicas):
    with pytest.raises(SeriesError, match="at least two runs") as error:
        replica_bands(replicas[:1])
    assert "\n" not in str(error.value)


def test_misaligned_replicas_name_the_run_and_the_stage(replicas, tmp_path):
    short = replica(tmp_path / "short", seed=9, increments=3)
    with pytest.raises(SeriesError) as error:
        replica_bands([replicas[0], short])
    message = str(error.value)
    assert "\n" not in message
    assert "'short'" in message and "stage 'A_to_B': 3 records against 4" in message, message


def test_command_line(replicas, tmp_path, capsys):
    out = tmp_path / "cli"
    argv = ["figure2", "--replicas", *map(str, replicas), "--out", str(out), "--quiet"]
    assert main(argv) == 0
    assert (out / "figure2_replicas.png").exists() and (out / "figure2_replicas.md").exists()
    capsys.readouterr()
    short = replica(tmp_path / "short", seed=9, increments=3)
    for runs, expected in (
        ([replicas[0]], "at least two runs"),
        ([replicas[0], short], "'A_to_B'"),
    ):
        code = main(["figure2", "--replicas", *map(str, runs), "--out", str(tmp_path / "x")])
        err = capsys.readouterr().err
        lines = [line for line in err.splitlines() if line.strip()]
        assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
        assert lines[0].startswith("python -m bridge figure2: error:") and expected in lines[0]
    (tmp_path / "file").write_text("x")
    assert (
        main(["figure2", "--replicas", *map(str, replicas), "--out", str(tmp_path / "file")]) == 2
    )
    assert "give a folder" in capsys.readouterr().err
    with pytest.raises(SeriesError):  # --debug: the traceback instead of the line
        main(["figure2", "--replicas", str(replicas[0]), "--out", str(out), "--debug"])


def _labelled_past_b(folder, seed, scale):
    """A synthetic run whose isotropic path went on past B (``isotropic_end_stress``): its
    records carry steps, and its summary.json labels B at the second-last A→B record."""
    replica(folder, seed, scale)
    ds = xr.load_dataset(folder / "relaxed_states.nc")
    ds["step"] = ("time", 1000.0 * np.arange(1, ds.sizes["time"] + 1))
    ds.to_netcdf(folder / "relaxed_states.nc")
    stages = [history_stage(ds, i) for i in range(ds.sizes["time"])]
    labels = record_labels(stages, ds["mean_stress"].values)
    iso = [i for i, s in enumerate(stages) if s == "A_to_B"]
    states = {
        str(label): {"stage": stages[i], "step": int(ds["step"].values[i])}
        for i, label in enumerate(labels)
        if label and label != "B"
    }
    states["B"] = {"stage": "A_to_B", "step": int(ds["step"].values[iso[-2]])}
    (folder / "summary.json").write_text(json.dumps({"states": states}))
    return iso[-2]


def test_labels_come_from_the_runs_summary_when_a_path_goes_on_past_its_state(tmp_path):
    runs = [tmp_path / f"seed-{k}" for k in (1, 2)]
    b = [_labelled_past_b(run, k, 1.0) for k, run in enumerate(runs, start=1)][0]
    bands = replica_bands(runs)
    labels = bands["state_label"].values.astype(str)
    assert np.flatnonzero(labels == "B").tolist() == [b]  # not the isotropic path's last record
    assert [x for x in labels if x] == ["A", "B", "C", "B'", "R1_end"]
    curves = study_curves(bands, TABLE1, substeps=2)
    table = figure2_markdown(bands, curves)
    row = next(line for line in table.splitlines() if line.startswith("| B |"))
    cells = [c.strip() for c in row.split("|")[1:-1]]
    p = bands["mean_stress"].values[b]
    assert cells[1] == f"{p:.4g} ± {bands['mean_stress_ci95'].values[b]:.2g}"
    iso = path_members(bands["stage"].values, labels, bands["mean_stress"].values)["isotropic"]
    point = 2 * int(np.flatnonzero(iso == b)[0])  # two substeps per interval
    assert point < curves["isotropic"].sizes["point"] - 1
    assert cells[2] == f"{float(curves['isotropic']['mean_stress'][point]):.4g}" == f"{p:.4g}"
    # without a summary (or without steps) the last record of the stage block is B, as before
    for run in runs:
        (run / "summary.json").unlink()
    labels = replica_bands(runs)["state_label"].values.astype(str)
    assert np.flatnonzero(labels == "B").tolist() == [b + 1]


def test_summary_labels_read_plain_json_and_refuse_nothing(tmp_path):
    assert summary_labels(tmp_path) is None  # no summary
    (tmp_path / "summary.json").write_text("not json")
    assert summary_labels(tmp_path) is None
    (tmp_path / "summary.json").write_text(json.dumps({"states": {"A": {"step": 3}}}))
    assert summary_labels(tmp_path) is None  # no stage: cannot be placed
    states = {"A": {"stage": "isotropic_to_A", "step": 3}, "B": {"stage": "A_to_B", "step": 9}}
    (tmp_path / "summary.json").write_text(json.dumps({"states": states}))
    assert summary_labels(tmp_path) == {("isotropic_to_A", 3): "A", ("A_to_B", 9): "B"}
    assert record_labels(
        ["isotropic_to_A", "A_to_B", "A_to_B"],
        [1.0, 2.0, 4.0],
        [3, 9, 12],
        summary_labels(tmp_path),
    ).tolist() == ["A", "B", ""]
