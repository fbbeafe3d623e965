"""The branches of the protocol from state A as a typed value (issue 21): :class:`Branch`
built and checked, its label the text the outputs have always carried, and read back from a
file only through :meth:`Branch.parse`, which refuses what this package does not write."""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest

from dem_taichi.protocol.branches import Branch, branch_labels, branch_names
from dem_taichi.protocol.records import BranchOutcome, RunLog
from dem_taichi.protocol.resume_codec import EncodingError, decode, encode
from dem_taichi.scene.protocol_sections import ProtocolConfig


# -- construction -----------------------------------------------------------------------------
def test_the_three_kinds_and_their_fields():
    assert Branch("isotropic") == Branch("isotropic", 0, None)
    assert Branch("k0").kind == "k0" and Branch("k0").index == 0 and Branch("k0").eta is None
    radial = Branch("radial", 2, 0.25)
    assert (radial.kind, radial.index, radial.eta) == ("radial", 2, 0.25)


def test_a_branch_is_frozen_and_hashable():
    branch = Branch("radial", 1, 0.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        branch.eta = 0.6  # type: ignore[misc]
    assert {branch: 1}[Branch("radial", 1, 0.5)] == 1
    assert Branch("radial", 1, 0.5) != Branch("radial", 2, 0.5) != Branch("radial", 2, 0.6)


def test_a_branch_crosses_to_a_worker_process():
    """The spawned branch processes get their branch, and hand back their outcome, pickled."""
    branch = Branch("radial", 3, -0.25)
    assert pickle.loads(pickle.dumps(branch)) == branch
    outcome = pickle.loads(pickle.dumps(BranchOutcome(branch, [], RunLog())))
    assert outcome.branch == branch and outcome.branch.label == "radial 3 -0.25"


def test_eta_is_kept_as_a_plain_float():
    """An int or numpy η becomes a float, so the label is the float's repr, as before."""
    from_int = Branch("radial", 1, 1)
    assert type(from_int.eta) is float and from_int.label == "radial 1 1.0"
    from_numpy = Branch("radial", 1, np.float64(0.1))
    assert type(from_numpy.eta) is float and from_numpy.label == "radial 1 0.1"


# -- validation -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("args", "words"),
    [
        (("shear",), ("'shear' is not a branch from A", "allowed")),
        (("",), ("is not a branch from A",)),
        (("isotropic", 1), ("takes no index or eta",)),
        (("k0", 0, 0.5), ("takes no index or eta",)),
        (("radial",), ("index 0 must be >= 1",)),
        (("radial", 0, 0.5), ("index 0 must be >= 1",)),
        (("radial", -1, 0.5), ("index -1 must be >= 1",)),
        (("radial", 1), ("eta None must be a finite number",)),
        (("radial", 1, math.nan), ("eta nan must be a finite number",)),
        (("radial", 1, math.inf), ("eta inf must be a finite number",)),
        (("radial", 1, "0.5"), ("eta '0.5' must be a finite number",)),
        (("radial", 1, True), ("eta True must be a finite number",)),
        (("radial", 1.0, 0.5), ("index 1.0 must be an int",)),
        (("radial", True, 0.5), ("index True must be an int",)),
        (("radial", np.int64(1), 0.5), ("must be an int",)),
    ],
)
def test_bad_branches_are_refused_saying_why(args, words):
    with pytest.raises(ValueError) as caught:
        Branch(*args)
    text = str(caught.value)
    assert "\n" not in text and all(w in text for w in words), text


# -- labels -----------------------------------------------------------------------------------
def test_labels_are_the_texts_of_earlier_versions():
    assert Branch("isotropic").label == str(Branch("isotropic")) == "isotropic"
    assert Branch("k0").label == "k0"
    assert Branch("radial", 1, 0.5).label == "radial 1 0.5"
    assert Branch("radial", 3, -0.75).label == "radial 3 -0.75"
    assert Branch("radial", 2, 0.1 + 0.2).label == "radial 2 0.30000000000000004"  # exact η
    assert Branch("radial", 1, 1e-20).label == "radial 1 1e-20"
    assert Branch("radial", 1, -0.0).label == "radial 1 -0.0"
    two = [Branch("isotropic"), Branch("radial", 1, 0.5)]
    assert branch_labels(two) == "isotropic, radial 1 0.5"
    assert branch_labels([]) == ""


def _config(**keys) -> ProtocolConfig:
    return dataclasses.replace(ProtocolConfig(), **keys)


def test_branch_names_in_the_order_of_the_serial_run():
    config = _config(run_isotropic=True, run_k0=True, radial_stress_ratios="0.5, -0.3, 1")
    branches = branch_names(config)
    assert branches == [
        Branch("isotropic"), Branch("k0"), Branch("radial", 1, 0.5), Branch("radial", 2, -0.3),
        Branch("radial", 3, 1.0),
    ]  # fmt: skip
    # the text the string version wrote: f"radial {k} {eta!r}" of the parsed floats
    old = ["isotropic", "k0"] + [
        f"radial {k} {eta!r}" for k, eta in enumerate(config.radial_ratios, 1)
    ]
    assert [b.label for b in branches] == old
    none = _config(run_isotropic=False, run_k0=False, run_unloading=False, radial_stress_ratios="")
    assert branch_names(none) == []


# -- reading back -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "branch",
    [
        Branch("isotropic"), Branch("k0"), Branch("radial", 1, 0.5), Branch("radial", 12, -0.3),
        Branch("radial", 2, 0.1 + 0.2), Branch("radial", 1, 1e-20), Branch("radial", 1, -0.0),
        Branch("radial", 1, 1.0),
    ],
)  # fmt: skip
def test_parse_reads_back_every_label(branch):
    parsed = Branch.parse(branch.label)
    assert parsed == branch and parsed.label == branch.label
    assert math.copysign(1.0, parsed.eta or 1.0) == math.copysign(1.0, branch.eta or 1.0)


@pytest.mark.parametrize(
    ("text", "words"),
    [
        ("", ("not of this form",)),
        ("shear", ("not of this form",)),
        ("Isotropic", ("not of this form",)),
        ("k0 ", ("not of this form",)),
        (" k0", ("not of this form",)),
        ("radial", ("not of this form",)),
        ("radial 1", ("not of this form",)),
        ("radial 1 0.5 2", ("not of this form",)),
        ("radial  1 0.5", ("not of this form",)),
        ("radial\t1\t0.5", ("not of this form",)),
        ("radial x 0.5", ("invalid literal for int()",)),
        ("radial 1 half", ("could not convert",)),
        ("radial 0 0.5", ("index 0 must be >= 1",)),
        ("radial 1 nan", ("eta nan must be a finite number",)),
        ("radial 1 0.50", ("is not written as 'radial 1 0.5'",)),
        ("radial 01 0.5", ("is not written as 'radial 1 0.5'",)),
        ("radial 1 .5", ("is not written as 'radial 1 0.5'",)),
        ("radial 1 1", ("is not written as 'radial 1 1.0'",)),
        ("radial 1 5e-1", ("is not written as 'radial 1 0.5'",)),
    ],
)
def test_parse_refuses_what_this_package_does_not_write(text, words):
    with pytest.raises(ValueError) as caught:
        Branch.parse(text)
    message = str(caught.value)
    assert "\n" not in message and repr(text) in message, message
    assert all(w in message for w in words) and "expected 'isotropic', 'k0'" in message, message


@pytest.mark.parametrize("value", [None, 3, ["k0"], b"k0"])
def test_parse_refuses_what_is_not_text(value):
    with pytest.raises(ValueError, match="is not text"):
        Branch.parse(value)


# -- the outcome of a branch and its storage ------------------------------------------------
def test_an_outcome_holds_a_branch_not_its_label():
    assert BranchOutcome(Branch("k0"), [], RunLog()).branch == Branch("k0")
    with pytest.raises(TypeError, match="must be a Branch, not 'k0'"):
        BranchOutcome("k0", [], RunLog())  # type: ignore[arg-type]


def test_a_stored_outcome_holds_the_label_and_reads_back_the_branch():
    """The resume files store the branch as the text earlier versions stored: files of either
    version read in the other."""
    outcome = BranchOutcome(Branch("radial", 2, 0.3), [{"step": 1}], RunLog())
    tree, arrays = encode(outcome)
    assert list(tree["$obj"][1]) == ["branch", "history", "log"]
    assert tree["$obj"][1]["branch"] == "radial 2 0.3"
    back = decode(tree, arrays)
    assert isinstance(back, BranchOutcome) and back.branch == Branch("radial", 2, 0.3)


@pytest.mark.parametrize(
    ("stored", "words"),
    [("radial 2 0.30", "is not written as"), ("shear", "not of this form"), (7, "found int")],
)
def test_a_stored_outcome_with_a_bad_branch_is_refused(stored, words):
    tree, arrays = encode(BranchOutcome(Branch("k0"), [], RunLog()))
    tree["$obj"][1]["branch"] = stored
    with pytest.raises(EncodingError, match="value.branch") as caught:
        decode(tree, arrays)
    assert words in str(caught.value)


def test_an_outcome_whose_branch_was_swapped_for_text_is_not_stored():
    outcome = BranchOutcome(Branch("k0"), [], RunLog())
    object.__setattr__(outcome, "branch", "k0")  # past __post_init__
    with pytest.raises(EncodingError, match="value.branch: 'k0' is not a Branch"):
        encode(outcome)
