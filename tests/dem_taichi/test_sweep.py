"""Sweeps on Dask (`dem_taichi.sweep.command`): the sweep file, a local-cluster run with a failing
member, the re-run, the combined dataset and the replica statistics.

The cluster test runs a reduced smoke protocol (no C→B, no radial path, one increment per path,
linear-response probes only at A, B, C) whose servo settles fast (servo time 0.5 instead of 2,
stresses held to 1 % instead of 0.1 %): ~7–11 s of CPU per member, most of it the compression to
A. What these tests check (failure, re-run, resume, the combined dataset) does not depend on how
closely a member holds its targets.
"""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from dem_taichi.analysis.findings import mean_interval
from dem_taichi.sweep.command import main, read_index, run_sweep
from dem_taichi.sweep.results import (
    open_relaxed_states,
    open_sweep,
    replica_statistics,
    summarise_sweep,
)
from dem_taichi.sweep.spec import SweepError, load_sweep, sweep_from_toml

REDUCED = """
[sweep.set]
"protocol.path_increments" = 1
"protocol.run_unloading" = false
"protocol.radial_stress_ratios" = ""
"probing.dynamic" = false
"probing.states" = "A, B, C"
"probing.every_n_increments" = 0
"protocol.servo_time" = 0.5
"protocol.stress_tolerance" = 1.0e-2
"protocol.servo_stiffness" = "secant"
"""


def test_grid_members_and_names():
    spec = sweep_from_toml(
        """
[sweep]
scene = "smoke"
[sweep.set]
"protocol.path_increments" = 1
[sweep.grid]
"scene.seed" = [1, 2]
contact.mu = [0.2, 0.5]
[[sweep.members]]
name = "soft"
"contact.k_t" = 1.0e4
[[sweep.members]]
"long_range.pattern" = "basic"
"""
    )
    names = [m.name for m in spec.members]
    assert names[:4] == [
        "soft__seed-1__mu-0.2",
        "soft__seed-1__mu-0.5",
        "soft__seed-2__mu-0.2",
        "soft__seed-2__mu-0.5",
    ]
    assert names[4] == "pattern-basic__seed-1__mu-0.2" and len(names) == 8
    first = spec.members[0]
    assert first.overrides == {
        "protocol.path_increments": 1,
        "contact.k_t": 1.0e4,
        "scene.seed": 1,
        "contact.mu": 0.2,
    }
    assert "k_t = 10000.0" in first.scene_toml and "seed = 1" in first.scene_toml
    assert spec.parameter_keys == ("contact.k_t", "scene.seed", "contact.mu", "long_range.pattern")
    assert len({m.scene_sha256 for m in spec.members}) == 8


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('[sweep]\nscene = "smoke"\ncolour = 1\n', "[sweep] unknown key(s) colour; allowed keys"),
        ('[sweep]\nscene = "nosuch"\n[sweep.grid]\n"scene.seed" = [1]\n', "no built-in scene"),
        ('[sweep]\nscene = "smoke"\narch = "tpu"\n', "allowed values are cpu | gpu"),
        ('[sweep]\nscene = "smoke"\n', "no members"),
        ('[sweep]\nscene = "smoke"\n[sweep.grid]\n"scene.seed" = 3\n', "non-empty list"),
        ('[sweep]\nscene = "smoke"\n[sweep.grid]\nseed = [1]\n', '"section.key"'),
        (
            '[sweep]\nscene = "smoke"\n[sweep.grid]\n"scene.sed" = [1, 2]\n',
            "member sed-1 (scene.sed = 1): [scene] unknown key(s) sed; allowed keys",
        ),
        (
            '[sweep]\nscene = "smoke"\n[sweep.grid]\n"contact.mu" = [0.5, -1.0]\n',
            "[contact] mu = -1.0 is out of range: allowed",
        ),
        (
            '[sweep]\nscene = "smoke"\n[[sweep.members]]\nname = "a"\n[[sweep.members]]\n'
            'name = "a"\n',
            "member name(s) a given to more than one member",
        ),
    ],
)
def test_invalid_sweep_fails_at_load_naming_the_key(text, expected):
    with pytest.raises(SweepError) as info:
        sweep_from_toml(text)
    assert expected in str(info.value)


def test_cli_invalid_sweep_one_line_without_traceback(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('[sweep]\nscene = "smoke"\n[sweep.grid]\n"particles.n_rods" = [0]\n')
    args = [sys.executable, "-m", "dem_taichi.sweep", str(path), "--out", str(tmp_path / "o")]
    result = subprocess.run(args, capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("python -m dem_taichi.sweep: error: member n_rods-0")
    assert "[particles] n_rods = 0" in lines[0] and "allowed" in lines[0]
    assert not (tmp_path / "o").exists()
    debug = subprocess.run([*args, "--debug"], capture_output=True, text=True, cwd=tmp_path)
    assert debug.returncode == 1 and "Traceback" in debug.stderr


def test_scene_file_relative_to_the_sweep_file(tmp_path):
    from dem_taichi.scene.config import builtin_scene_path

    (tmp_path / "scenes").mkdir()
    text = builtin_scene_path("smoke").read_text().replace("n_rods = 40", "n_rods = 30")
    (tmp_path / "scenes" / "mine.toml").write_text(text)
    (tmp_path / "s.toml").write_text(
        '[sweep]\nscene = "scenes/mine.toml"\n[sweep.grid]\n"scene.seed" = [4]\n'
    )
    spec = load_sweep(tmp_path / "s.toml")
    assert spec.name == "s" and "n_rods = 30" in spec.members[0].scene_toml
    (tmp_path / "s.toml").write_text('[sweep]\nscene = "scenes/none.toml"\n')
    with pytest.raises(SweepError, match="does not exist"):
        load_sweep(tmp_path / "s.toml")


def test_plan_reruns_unfinished_and_failed_members_and_refuses_changed_ones(tmp_path):
    """Without a cluster: what a re-run would do with the members' records."""
    from dem_taichi.sweep.client import _plan
    from dem_taichi.sweep.member import member_dir, write_json

    spec = sweep_from_toml('[sweep]\nscene = "smoke"\n[sweep.grid]\n"scene.seed" = [1, 2, 3, 4]\n')
    done, running, failed, fresh = spec.members
    for member, status in ((done, "done"), (running, "running"), (failed, "failed")):
        folder = member_dir(tmp_path, member.name)
        write_json(folder / "member.json", {"status": status, "error": "ProtocolError: x",
                                            "scene_sha256": member.scene_sha256})  # fmt: skip
        (folder / "summary.json").write_text("{}")
    to_run, skipped, why = _plan(spec, tmp_path, overwrite=False)
    assert [m.name for m in to_run] == [running.name, failed.name, fresh.name]
    assert skipped == [done.name]
    assert why[running.name] == "unfinished; it had not saved state A: runs again from the gas"
    assert "failed before (ProtocolError: x)" in why[failed.name]
    # a member stopped inside its ageing stage resumes from that save (resume/ageing.npz)
    folder = member_dir(tmp_path, running.name)
    write_json(folder / "run.json", {"scene_sha256": running.scene_sha256})
    (folder / "resume").mkdir()
    (folder / "resume" / "ageing.npz").write_bytes(b"")
    why = _plan(spec, tmp_path, overwrite=False)[2]
    assert why[running.name] == (
        "unfinished; resumes from its last save inside the ageing stage (state A not reached)"
    )
    changed = sweep_from_toml(
        '[sweep]\nscene = "smoke"\n[sweep.set]\n"contact.mu" = 0.3\n[sweep.grid]\n'
        '"scene.seed" = [1]\n'
    )
    with pytest.raises(SweepError, match="seed-1 .* another scene .* --overwrite"):
        _plan(changed, tmp_path, overwrite=False)
    assert [m.name for m in _plan(changed, tmp_path, overwrite=True)[0]] == ["seed-1"]
    foreign = member_dir(tmp_path, fresh.name)
    foreign.mkdir(parents=True)
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(SweepError, match="not written by a sweep"):
        _plan(spec, tmp_path, overwrite=False)


def test_mean_interval_is_student_t():
    mean, half, n = mean_interval([1.0, 2.0, 3.0, math.nan])
    assert (mean, n) == (2.0, 3)
    assert half == pytest.approx(4.302652729911275 / math.sqrt(3))  # t(0.975, 2) · s/√n
    assert mean_interval([5.0])[1] != mean_interval([5.0])[1]  # NaN half-width for one value
    assert mean_interval([])[2] == 0


def test_local_cluster_sweep_with_a_failing_member_and_a_rerun(tmp_path, capsys):
    """Three members on a local cluster of 2 processes, one made to fail (its compression gives
    up after one increment); the others finish and the failure is reported with its reason.
    After the fix, a re-run (on an existing scheduler) runs only the failed member, and the
    three open as one dataset along ``member``."""
    from distributed import LocalCluster

    members = """
[[sweep.members]]
"scene.seed" = 1
[[sweep.members]]
name = "broken"
"scene.seed" = 3
{broken}
[[sweep.members]]
"scene.seed" = 2
"""
    sweep_file = tmp_path / "smoke.toml"
    head = '[sweep]\nname = "smoke-test"\nscene = "smoke"\n' + REDUCED
    sweep_file.write_text(head + members.format(broken='"protocol.max_compression_increments" = 1'))
    out = tmp_path / "sweep"
    assert main([str(sweep_file), "--out", str(out), "--n-workers", "2"]) == 1
    printed = capsys.readouterr().out
    assert "broken: FAILED: ProtocolError: no fluid–solid transition after 1" in printed
    assert "seed-1: done" in printed and "seed-2: done" in printed
    assert "seed-1: started" in printed
    index = read_index(out)
    status = {r["name"]: r["status"] for r in index["members"]}
    assert status == {"seed-1": "done", "broken": "failed", "seed-2": "done"}
    failed = [r for r in index["members"] if r["name"] == "broken"][0]
    assert "max_compression_increments" in failed["error"]
    record = json.loads((out / "members" / "broken" / "member.json").read_text())
    assert "Traceback" in record["traceback"]
    assert (out / "index.csv").read_text().splitlines()[0].startswith("name,status,seconds")
    partial = open_sweep(out)
    assert list(partial["member"].values) == ["seed-1", "seed-2"]
    assert partial.attrs["members_not_finished"] == "broken"
    written = {
        n: (out / "members" / n / "summary.json").stat().st_mtime_ns for n in ("seed-1", "seed-2")
    }

    # the fix, and a re-run on an existing scheduler: only the failed member runs
    sweep_file.write_text(head + members.format(broken=""))
    spec = load_sweep(sweep_file)
    with LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        outcome = run_sweep(spec, out, scheduler=cluster.scheduler_address, say=lambda _: None)
    assert outcome.ran == ["broken"] and sorted(outcome.skipped) == ["seed-1", "seed-2"]
    assert outcome.failed == [] and sorted(outcome.done) == ["broken", "seed-1", "seed-2"]
    for name, mtime in written.items():  # the finished members were not touched
        assert (out / "members" / name / "summary.json").stat().st_mtime_ns == mtime

    ds = open_sweep(out)
    assert list(ds["member"].values) == ["seed-1", "broken", "seed-2"]
    assert list(ds["state"].values) == ["A", "B", "C"]
    assert list(ds["scene_seed"].values) == [1, 3, 2]
    assert ds["scene_seed"].attrs["sweep_key"] == "scene.seed"
    summary = json.loads((out / "members" / "seed-2" / "summary.json").read_text())
    assert ds["specific_volume"].sel(member="seed-2", state="C") == pytest.approx(
        summary["states"]["C"]["specific_volume"]
    )
    c = summary["states"]["C"]
    assert ds["k0_at_C"].sel(member="seed-2") == pytest.approx(c["stress_xx"] / c["stress_yy"])
    assert np.all(np.isfinite(ds["e_ratio"].values)) and np.all(ds["e_oed_v"].values > 0)

    # a run made outside the sweep (here a copy of a member) pools as one more replica
    import shutil

    earlier = tmp_path / "earlier_run"
    shutil.copytree(out / "members" / "seed-2", earlier)
    pooled = open_sweep(out, extra_runs=[earlier])
    assert list(pooled["member"].values) == ["seed-1", "broken", "seed-2", "earlier_run"]
    assert list(pooled["scene_seed"].values) == [1, 3, 2, 2]
    assert pooled.attrs["extra_runs"] == str(earlier)
    with pytest.raises(ValueError, match="distinct"):
        open_sweep(out, extra_runs=[out / "members" / "seed-1"])

    relaxed = open_relaxed_states(out)
    assert relaxed.sizes["member"] == 3 and "A_to_C" in set(relaxed["stage_label"].values.ravel())
    on_c = relaxed["stage_label"].sel(member="seed-2").values == "A_to_C"
    assert relaxed["specific_volume"].sel(member="seed-2").values[on_c][-1] == pytest.approx(
        summary["states"]["C"]["specific_volume"]
    )

    # replica statistics: mean ± Student-t interval over the three seeds, table and figure
    stats = replica_statistics(ds)
    (group,) = stats.values()
    v_c = group["findings"]["v at C"]
    expected = mean_interval(ds["specific_volume"].sel(state="C").values)
    assert (v_c["mean"], v_c["half"], v_c["n"]) == pytest.approx(expected)
    files = summarise_sweep(out)
    table = (out / "replica_summary.md").read_text()
    assert "| E_h/E_v at C |" in table and "| K0 = σ_xx/σ_yy at C |" in table
    assert (out / "replica_summary.png").stat().st_size > 0
    reopened = xr.open_dataset(files["dataset"])
    assert reopened.sizes == {"member": 3, "state": 3}
    reopened.close()


@pytest.mark.parametrize(
    "path", sorted((Path(__file__).resolve().parents[2] / "benchmarks" / "sweeps").glob("*.toml"))
)
def test_shipped_sweep_files_load(path):
    spec = load_sweep(path)
    assert spec.members and spec.name == path.stem


def test_unfinished_member_resumes_from_its_saved_state_a(tmp_path, monkeypatch):
    """A member that failed in its second branch from A (here: made to) is run again from the
    saved state A with its finished first branch, not from the gas; then it is done."""
    import dem_taichi.protocol.branches as branches
    from dem_taichi.sweep.member import run_member

    spec = sweep_from_toml(
        '[sweep]\nscene = "smoke"\n' + REDUCED + '[sweep.grid]\n"scene.seed" = [1]\n'
    )
    member = spec.members[0]
    out = tmp_path / "members" / member.name
    original = branches.run_branch_on

    def fail_at_k0(runner, branch):
        if branch.kind == "k0":
            raise RuntimeError("made to fail")
        return original(runner, branch)

    monkeypatch.setattr(branches, "run_branch_on", fail_at_k0)
    first = run_member(member.name, member.scene_toml, str(out))
    assert first["status"] == "failed" and "made to fail" in first["error"]
    assert (out / "resume" / "A.npz").exists() and (out / "resume" / "branch_0.npz").exists()
    a_saved = (out / "resume" / "A.npz").stat().st_mtime_ns

    monkeypatch.setattr(branches, "run_branch_on", original)
    second = run_member(member.name, member.scene_toml, str(out))
    assert second["status"] == "done" and second["resumed"] is True
    assert (out / "resume" / "A.npz").stat().st_mtime_ns == a_saved  # A was not run again
    assert (
        "[resume] from state A; branches done: isotropic; to run: k0"
        in (out / "progress.log").read_text()
    )
    assert sorted(second["states"]) == ["A", "B", "C"]
