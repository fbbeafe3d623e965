"""A branch stopped part-way goes on from its last point (``resume/branch_<k>_point.npz``,
:class:`dem_taichi.protocol.resume.BranchPoint`): bitwise, from every kind of point, serial and
in worker processes; and a damaged or foreign point is refused."""

from __future__ import annotations

import shutil

import pytest

from .test_protocol import REFERENCE_SECANT, _assert_bitwise_equal, _outputs, smoke_protocol_scene
from .test_protocol_resume import _release_runs


@pytest.fixture(scope="module")
def stopped_at_every_point(tmp_path_factory):
    """The smoke protocol (serial) with a point after every path state, stopped by a
    KeyboardInterrupt right after each point is saved, the first time it is, then resumed,
    until it finishes: every point of every branch (inside A→B, A→C, at C, inside C→B′,
    inside the radial path) is gone on from once. Returns (the run's folder, the points in
    the order they stopped the run, the finished run's result, a copy of the folder taken
    at the stop inside C→B′)."""
    import dem_taichi.protocol.branches as branches
    import dem_taichi.protocol.paths as paths
    from dem_taichi.protocol.runner import run_protocol

    out = tmp_path_factory.mktemp("branch_points")
    copy = tmp_path_factory.mktemp("branch_points_copy") / "run"
    original_save, original_seconds = branches.save_branch_point, paths.BRANCH_SAVE_SECONDS
    stops: list[tuple[str, str, int]] = []

    def save_then_stop(run, index, branch, point):
        path = original_save(run, index, branch, point)
        where = (branch.label, point.progress["stage"], point.progress["increment"])
        if where not in stops:
            stops.append(where)
            if where[1] == "C_to_B" and where[2] == 1:
                shutil.copytree(out, copy, ignore=shutil.ignore_patterns("run.lock"))
            raise KeyboardInterrupt
        return path

    branches.save_branch_point, paths.BRANCH_SAVE_SECONDS = save_then_stop, 0.0
    try:
        result, resume = None, False
        for _ in range(20):
            try:
                result = run_protocol(smoke_protocol_scene(), out, resume=resume)
                break
            except KeyboardInterrupt:
                _release_runs()
                resume = True
    finally:
        branches.save_branch_point, paths.BRANCH_SAVE_SECONDS = original_save, original_seconds
    _release_runs()
    assert result is not None, f"the run did not finish after {len(stops)} stops"
    return out, stops, result, copy


def test_every_kind_of_point_was_gone_on_from(stopped_at_every_point):
    _, stops, _, _ = stopped_at_every_point
    stages = {(label, stage) for label, stage, _ in stops}
    assert ("isotropic", "A_to_B") in stages
    assert ("k0", "A_to_C") in stages
    assert ("k0", "C_to_B") in stages
    assert any(label.startswith("radial") and stage == "radial" for label, stage in stages)
    assert ("k0", "C_to_B", 0) in stops  # at C, before the unloading
    assert ("k0", "C_to_B", 1) in stops  # inside the unloading


def test_a_run_stopped_at_every_point_equals_the_run_never_stopped_bitwise(
    stopped_at_every_point,
):
    out, _, result, _ = stopped_at_every_point
    assert list(result.states) == ["A", "B", "C", "B'", "R1_end"]
    _assert_bitwise_equal(_outputs(result, history=True), REFERENCE_SECANT)
    assert not list((out / "resume").glob("branch_*_point.npz"))  # spent once saved


def test_worker_processes_go_on_from_a_point(stopped_at_every_point):
    """The copy taken at the stop inside C→B′ (A→B saved, the K0 branch part-way, the radial
    path not begun), resumed with two worker processes: the K0 branch's process goes on from
    the point and the outputs equal the reference bit for bit."""
    from dem_taichi.protocol.records import Branch
    from dem_taichi.protocol.resume import saved_summary
    from dem_taichi.protocol.runner import run_protocol

    _, _, _, copy = stopped_at_every_point
    assert (copy / "resume" / "branch_1_point.npz").exists()
    branches = [Branch("isotropic"), Branch("k0"), Branch("radial", 1, 0.4)]
    assert saved_summary(copy, branches) == (
        "state A and 1 of 3 branches from A are saved, and part of k0"
    )
    result = run_protocol(smoke_protocol_scene(), copy, resume=True, workers=2)
    _release_runs()
    _assert_bitwise_equal(_outputs(result, history=True), REFERENCE_SECANT)
    assert not (copy / "resume" / "branch_1_point.npz").exists()


def _empty_run(folder):
    """A run identity over ``folder`` with an empty ``resume/`` (points and outcomes saved by
    hand)."""
    from dem_taichi.protocol.resume import RunIdentity

    (folder / "resume").mkdir()
    return RunIdentity(folder, "run-1", "0" * 64)


def test_a_point_of_another_run_or_branch_or_damaged_is_refused(stopped_at_every_point, tmp_path):
    from dem_taichi.protocol.records import Branch, RunLog
    from dem_taichi.protocol.resume import (
        BranchPoint,
        ResumeFileError,
        RunIdentity,
        branch_point_file,
        load_branch_point,
        save_branch_point,
    )

    run = _empty_run(tmp_path)
    k0 = Branch("k0")
    progress = {"stage": "C_to_B", "increment": 1, "measures": {"mean_stress": 1.0},
                "since_output": 3, "servo_times": {"C_to_B": 2.0}}  # fmt: skip
    save_branch_point(run, 1, k0, BranchPoint([], RunLog(), {}, progress))
    point = load_branch_point(run, 1, k0)
    assert point is not None and point.progress == progress
    assert load_branch_point(run, 0, Branch("isotropic")) is None  # none saved
    with pytest.raises(ResumeFileError, match="not by this folder's run"):
        load_branch_point(RunIdentity(tmp_path, "run-2", "0" * 64), 1, k0)
    with pytest.raises(ResumeFileError, match="holds branch 'k0', not 'radial 2 0.5'"):
        load_branch_point(run, 1, Branch("radial", 2, 0.5))
    with pytest.raises(ResumeFileError, match="inside A_to_B, which the branch 'k0'"):
        bad = dict(progress, stage="A_to_B")
        save_branch_point(run, 1, k0, BranchPoint([], RunLog(), {}, bad))
        load_branch_point(run, 1, k0)
    branch_point_file(tmp_path, 1).write_bytes(b"not a checkpoint")
    with pytest.raises(ResumeFileError, match="damaged or not a resume file"):
        load_branch_point(run, 1, k0)


def test_a_point_left_beside_its_saved_outcome_is_spent(tmp_path):
    """A run stopped between saving a branch's outcome and deleting its point leaves both; the
    next load of the outcomes deletes the point (it is never gone on from), and keeps the point
    of a branch without an outcome."""
    from dem_taichi.protocol.records import Branch, BranchOutcome, RunLog
    from dem_taichi.protocol.resume import (
        BranchPoint,
        branch_point_file,
        load_branches,
        save_branch,
        save_branch_point,
    )

    run = _empty_run(tmp_path)
    branches = [Branch("isotropic"), Branch("k0")]
    progress = {"stage": "A_to_B", "increment": 2, "measures": {"mean_stress": 1.0},
                "since_output": 0, "servo_times": {}}  # fmt: skip
    save_branch_point(run, 0, branches[0], BranchPoint([], RunLog(), {}, progress))
    save_branch(run, 0, BranchOutcome(branch=branches[0], history=[], log=RunLog()))
    k0_progress = dict(progress, stage="A_to_C", servo_times={"A_to_C": 2.0})
    save_branch_point(run, 1, branches[1], BranchPoint([], RunLog(), {}, k0_progress))
    done = load_branches(run, branches)
    assert list(done) == [branches[0]]
    assert not branch_point_file(tmp_path, 0).exists()
    assert branch_point_file(tmp_path, 1).exists()
