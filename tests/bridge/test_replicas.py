"""Calibration on replicas (bridge.replicas): the mean files, the spread, the command line."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr

from bridge.pipeline import calibrate_on_replicas, main, synthetic_inputs
from bridge.replicas import parameter_spread, replica_mean, replica_runs
from bridge.series import SeriesError


def replica(folder, seed, noise=0.01, increments=5):
    """A synthetic protocol run folder (relaxed_states.nc, probes.nc): the model with noise."""
    history, probes, truth = synthetic_inputs(folder, increments=increments, seed=seed, noise=noise)
    history.rename(folder / "relaxed_states.nc")
    probes.rename(folder / "probes.nc")
    return folder, truth


@pytest.fixture(scope="module")
def replicas(tmp_path_factory):
    root = tmp_path_factory.mktemp("replicas")
    return [replica(root / f"seed-{k}", seed=k)[0] for k in (1, 2, 3)]


def test_mean_files_are_the_record_by_record_means(replicas):
    history, probes = replica_mean(replicas)
    runs = [xr.load_dataset(r / "relaxed_states.nc") for r in replicas]
    # the same records (state A onwards) in each synthetic run: the mean is the plain mean
    n = history.sizes["time"]
    for name in ("specific_volume", "mean_stress", "fabric_deviator"):
        stacked = np.stack([ds[name].values[-n:] for ds in runs])
        np.testing.assert_allclose(history[name].values, stacked.mean(axis=0), rtol=1e-12)
    np.testing.assert_array_equal(history["stage"].values, runs[0]["stage"].values[-n:])
    assert history.attrs["replicas"] == 3
    assert (
        probes is not None
        and probes.sizes["probe"] == xr.load_dataset(replicas[0] / "probes.nc").sizes["probe"]
    )


def test_replicas_of_other_protocols_are_refused(tmp_path, replicas):
    other, _ = replica(tmp_path / "short", seed=9, increments=3)
    with pytest.raises(SeriesError, match="other stages or record counts"):
        replica_mean([replicas[0], other])
    with pytest.raises(SeriesError, match="at least two runs"):
        replica_runs([replicas[0]])
    with pytest.raises(SeriesError, match="neither a protocol run"):
        replica_runs([tmp_path / "nowhere", replicas[0]])


def test_parameter_spread_combines_fit_error_and_replica_spread():
    mean = {"parameters": {"k": 70.0, "g": 40.0}, "standard_errors": {"k": 1.0}}
    fits = {f"r{i}": {"parameters": {"k": v, "g": 40.0}} for i, v in enumerate((68.0, 70.0, 72.0))}
    row = parameter_spread(mean, fits)["k"]
    assert row["replica_sd"] == pytest.approx(2.0)
    assert row["replica_interval_95"] == pytest.approx(4.302653 * 2.0 / math.sqrt(3), rel=1e-5)
    assert row["combined_uncertainty"] == pytest.approx(math.sqrt(1.0 + 4.0 / 3.0))
    assert row["fitted"] and not parameter_spread(mean, fits)["g"]["fitted"]


def test_calibrate_replicas_end_to_end(tmp_path, replicas):
    options = {"figures": False, "identifiability": False}
    result = calibrate_on_replicas(replicas, tmp_path / "out", options, say=lambda *_: None)
    truth = replica(tmp_path / "t", seed=0)[1].as_symbols()
    assert set(result["replicas"]) == {"seed-1", "seed-2", "seed-3"}
    for symbol in ("k", "g", "lambda_star", "N"):
        row = result["parameters"][symbol]
        assert row["fitted"]
        assert row["replica_sd"] > 0 and math.isfinite(row["combined_uncertainty"])
        # the noise is 1 %: the estimate on the mean is near the generating value
        assert row["estimate"] == pytest.approx(truth[symbol], rel=0.1), symbol
    saved = json.loads((tmp_path / "out" / "replicas.json").read_text())
    assert saved["parameters"]["k"]["estimate"] == result["parameters"]["k"]["estimate"]
    assert "| k |" in (tmp_path / "out" / "replicas.md").read_text()


def test_command_line_replicas(tmp_path, replicas, capsys):
    code = main(["--replicas", *map(str, replicas), "--out", str(tmp_path / "cli")]
                + ["--no-figures", "--no-identifiability", "--quiet"])  # fmt: skip
    assert code == 0 and (tmp_path / "cli" / "replicas.md").exists()
    code = main(["--replicas", str(replicas[0]), "--history", "h.nc", "--out", str(tmp_path)])
    assert code == 2
    assert "leave out --history" in capsys.readouterr().err
    code = main(["--replicas", str(replicas[0]), "--out", str(tmp_path / "one")])
    assert code == 2
    assert "at least two runs" in capsys.readouterr().err


@pytest.mark.parametrize(
    "fault",
    ["2-D stress", "other record dimension", "missing stage", "text", "probes without path"],
)
def test_a_wrongly_shaped_replica_is_one_line_naming_the_file(tmp_path, replicas, capsys, fault):
    """Issue 22: a replica's netCDF of the wrong shape was 'internal error: time (KeyError)';
    now one line, exit code 2, naming the replica file."""
    bad, _ = replica(tmp_path / "bad", seed=5)
    name = "probes.nc" if fault == "probes without path" else "relaxed_states.nc"
    path = bad / name
    ds = xr.load_dataset(path)
    if fault == "2-D stress":
        ds["stress_xx"] = (("time", "k"), np.stack([ds["stress_xx"].values] * 2, axis=1))
    elif fault == "other record dimension":
        ds = ds.rename({"time": "record"})
    elif fault == "missing stage":
        ds = ds.drop_vars("stage")
    elif fault == "text":
        ds["specific_volume"] = ("time", np.array(["x"] * ds.sizes["time"], dtype=object))
    else:
        ds = ds.drop_vars("path")
    path.unlink()
    ds.to_netcdf(path)
    capsys.readouterr()
    argv = ["--replicas", str(replicas[0]), str(bad), "--out", str(tmp_path / "cli"), "--quiet"]
    assert main([*argv, "--no-figures", "--no-identifiability"]) == 2
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in err and "internal error" not in err, err
    assert str(path) in lines[0], err
