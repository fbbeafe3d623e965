"""The work ledger (dem_taichi/engine/work_profile.py): what a protocol's steps were spent on."""

import json

import pytest

from dem_taichi.engine.work_profile import (
    add_work,
    current_work,
    doing,
    merge_work,
    overhead_seconds,
    stage_totals,
    work_rows,
)
from dem_taichi.protocol.records import RunLog
from dem_taichi.protocol.resume_codec import decode, encode


def test_labels_nest_and_unwind():
    assert current_work() == "other"
    with doing("servo"):
        assert current_work() == "servo"
        with doing("relax"):
            assert current_work() == "servo/relax"
        assert current_work() == "servo"
    assert current_work() == "other"


def test_a_label_unwinds_after_an_error():
    with pytest.raises(RuntimeError), doing("probe"):
        raise RuntimeError("boom")
    assert current_work() == "other"


@pytest.mark.parametrize("label", ["", "a/b"])
def test_bad_labels_are_refused(label):
    with pytest.raises(ValueError, match="work label"), doing(label):
        pass


def test_as_a_decorator_each_call_has_its_label():
    @doing("relax")
    def inner():
        return current_work()

    with doing("confirm"):
        assert inner() == "confirm/relax"
    assert inner() == "relax"


def test_sums_merge_and_overhead_are_exact():
    a: dict = {}
    add_work(a, "A_to_B", "servo", 100, 1.0, 0.5)
    add_work(a, "A_to_B", "servo", 100, 1.0, 0.25)
    add_work(a, "A_to_B", "servo/relax", 500, 2.0, 0.25)
    b: dict = {}
    add_work(b, "A_to_B", "servo/relax", 50, 0.5, 0.0)
    add_work(b, "radial", "servo", 10, 0.125, 0.0)
    merge_work(a, b)
    assert a["A_to_B"]["servo"] == [200, 2.0, 0.75, 2]
    assert a["A_to_B"]["servo/relax"] == [550, 2.5, 0.25, 2]
    assert a["radial"]["servo"] == [10, 0.125, 0.0, 1]
    assert stage_totals(a, "A_to_B") == (750, 4.5, 1.0, 4)
    assert overhead_seconds(a, "A_to_B", 6.0) == pytest.approx(0.5)
    rows = work_rows(a, {"A_to_B": 6.0})
    assert [(r["stage"], r["work"]) for r in rows] == [
        ("A_to_B", "servo"),
        ("A_to_B", "servo/relax"),
        ("A_to_B", "overhead"),
        ("radial", "servo"),
    ]
    assert rows[0]["share_of_steps"] == pytest.approx(200 / 750)
    assert rows[2]["overhead_seconds"] == pytest.approx(0.5)
    json.dumps(rows)  # summary.json holds them


def test_the_ledger_travels_in_the_run_log_and_its_resume_encoding():
    log = RunLog()
    add_work(log.work, "isotropic_to_A", "search/relax", 1234, 0.1, 0.2)
    tree, arrays = encode(log)
    back = decode(json.loads(json.dumps(tree)), arrays)
    assert back.work == log.work
    branch = RunLog()
    add_work(branch.work, "isotropic_to_A", "search/relax", 6, 0.0, 0.0)
    log.merge(branch)
    assert log.work["isotropic_to_A"]["search/relax"][0] == 1240


def test_a_resume_file_written_before_the_ledger_still_reads():
    tree, arrays = encode(RunLog())
    del tree["$obj"][1]["work"]  # a file of the version before RunLog.work
    assert decode(tree, arrays).work == {}


def test_an_unknown_field_is_still_refused():
    tree, arrays = encode(RunLog())
    tree["$obj"][1]["payload"] = 1
    with pytest.raises(ValueError, match="not the expected"):
        decode(tree, arrays)
