"""``benchmarks/probe_relaxation.py``: the probes' relaxation threshold measured from one saved
state, paired and bitwise (issue 20).

The run folder is made here, not by the protocol (a minute): a smoke sample compressed past
jamming and relaxed only loosely (UFR < 1e-4, as a path state is), saved as ``state_A.npz``
with a ``run.json`` naming its scene's hash, as a protocol run with ``save_states`` leaves it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from tests.scripts import load_script

THRESHOLDS = (1e-5, 1e-6, 1e-7)


@pytest.fixture(scope="module")
def bench():
    return load_script("benchmarks/probe_relaxation.py")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """A run folder holding one loosely relaxed dense smoke state, ``state_A.npz``."""
    from dem_taichi.engine.simulation import CellControl, Simulation
    from dem_taichi.io.run_directory import scene_sha256
    from dem_taichi.protocol.quasistatic import relax
    from dem_taichi.scene.config import load_scene, scene_to_toml

    folder = tmp_path_factory.mktemp("run")
    sim = Simulation(load_scene("smoke"))
    while sim.measure()["specific_volume"] > 1.8:
        sim.run(1000, CellControl.strain_rate(0.02, stage="isotropic_to_A"))
    measures, ok, _ = relax(sim, "relax", 1e-4, 1.0, 500, 60_000)
    assert ok and measures["mean_stress"] > 1.0
    sim.save_checkpoint(folder / "state_A.npz")
    record = {"scene_sha256": scene_sha256(scene_to_toml(sim.scene))}
    (folder / "run.json").write_text(json.dumps(record))
    return folder


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def measured(bench, run_dir, tmp_path_factory):
    """The benchmark's JSON and markdown over the thresholds, with the repeat."""
    out = tmp_path_factory.mktemp("out")
    before = _digest(run_dir / "state_A.npz")
    argv = [str(run_dir), "--ufr", *map(str, THRESHOLDS), "--repeat"]
    argv += ["--out", str(out / "r.json"), "--markdown", str(out / "r.md")]
    assert bench.main(argv) == 0
    assert _digest(run_dir / "state_A.npz") == before  # the saved state is only read
    return json.loads((out / "r.json").read_text()), (out / "r.md").read_text()


def test_every_threshold_starts_from_the_saved_state_and_leaves_it(measured):
    report, _ = measured
    rows = report["rows"]
    assert sorted(r["ufr"] for r in rows) == sorted(THRESHOLDS)
    assert all(r["started_bitwise"] and r["restored_bitwise"] for r in rows)
    # the loosest probed again, after the others, gives bitwise the same numbers
    assert [r["repeat_identical"] for r in rows if r["ufr"] == max(THRESHOLDS)] == [True]


def test_differences_are_against_the_strictest_and_steps_grow_as_it_tightens(measured):
    report, text = measured
    rows = sorted(report["rows"], key=lambda r: -r["ufr"])
    strictest = rows[-1]
    assert strictest["ufr"] == min(THRESHOLDS)
    assert strictest["d_e_oed_v"] == strictest["d_e_oed_h"] == strictest["d_ratio"] == 0.0
    assert all(r["relaxed"] for r in rows)
    assert all(r["final_ufr"] < r["ufr"] for r in rows)
    steps = [r["relax_steps"] for r in rows]
    assert steps == sorted(steps) and steps[-1] > steps[0], steps
    # the looser relaxations stop elsewhere: their moduli differ, a little
    loosest = rows[0]
    assert loosest["d_e_oed_v"] != 0.0 and abs(loosest["d_e_oed_v"]) < 1e-2
    assert loosest["e_oed_h"] / loosest["e_oed_v"] == loosest["ratio"]
    fractions = [s["steps_fraction"] for s in report["summary"]]
    assert fractions[-1] == 1.0 and fractions == sorted(fractions)
    assert f"| {min(THRESHOLDS):g} | 1 | 0 | 0.00e+00 | 0.00e+00 |" in text
    assert "identical" in text


def test_a_relaxation_that_does_not_reach_its_threshold_is_reported(bench, run_dir, tmp_path):
    argv = [str(run_dir), "--ufr", "1e-12", "1e-5", "--relax-max-steps", "500"]
    argv += ["--out", str(tmp_path / "r.json"), "--markdown", str(tmp_path / "r.md")]
    assert bench.main(argv) == 0
    report = json.loads((tmp_path / "r.json").read_text())
    strict = next(r for r in report["rows"] if r["ufr"] == 1e-12)
    assert not strict["relaxed"] and strict["relax_steps"] == 500 and strict["final_ufr"] > 1e-12
    assert report["summary"][-1]["not_reached"] == 1
    text = (tmp_path / "r.md").read_text()
    assert "| **1** |" in text and "**no**" in text
    assert "The strictest threshold was not reached at" in text


def test_a_state_of_another_scene_is_refused(bench, run_dir, tmp_path):
    foreign = tmp_path / "run"
    foreign.mkdir()
    (foreign / "state_A.npz").write_bytes((run_dir / "state_A.npz").read_bytes())
    (foreign / "run.json").write_text(json.dumps({"scene_sha256": "0" * 64}))
    with pytest.raises(SystemExit, match="holds another scene"):
        bench.main([str(foreign), "--ufr", "1e-5", "--out", str(tmp_path / "r.json")])
