"""Validation on the `default` scene (slow): the study's findings, for acidic, basic, neutral.

These are what the study reports (docs/science/dem-model.md §1 and §1.6), checked against what
the DEM gives —
not targets the code was tuned to. Each pattern runs the whole protocol of the `default` scene
(4–19 min each on a 2-core CPU, measured 2026-11-30); set ``DEM_VALIDATION_DIR`` to a folder holding
``default_<pattern>/`` results of ``python -m dem_taichi.protocol default --pattern <pattern>
--out DIR/default_<pattern>`` to check existing runs instead of running them again.

Findings checked:
- along the isotropic path (A and A→B) the rod fabric stays isotropic within 3 × the sampling
  noise sqrt(0.5/N), and E_oed,v ≈ E_oed,h (within 15 %, linear response);
- along K0 (A→C) the fabric deviator β_yy − β_xx decreases (rods lie down) by more than
  3 × the noise, and E_oed,h/E_oed,v > 1 and grows with p;
- ln v is roughly linear in ln p beyond A along A→B (R² ≥ 0.9);
- acidic samples are looser than basic ones: higher v at the same p (at B and at C).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from dem_taichi.analysis.arrays import fabric_sampling_noise
from dem_taichi.io import open_history, open_probes
from dem_taichi.io.schema import stage_code

pytestmark = [pytest.mark.slow, pytest.mark.validation]

PATTERNS = ("acidic", "basic", "neutral")
TOL = 1e-3


class Run:
    """Results of one protocol run read back from its files."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.summary = json.loads((folder / "summary.json").read_text())
        self.relaxed = open_history(folder / "relaxed_states.nc")
        self.probes = open_probes(folder / "probes.nc")
        self.n_rods = int(self.summary["n_rods"])

    def path(self, stage: str) -> dict[str, np.ndarray]:
        mask = self.relaxed["stage"].values == stage_code(stage)
        return {name: self.relaxed[name].values[mask] for name in self.relaxed.data_vars}

    def probe_rows(self, paths: tuple[str, ...]) -> dict[str, np.ndarray]:
        labels = self.probes["state_label"].values.astype(str)
        where = np.isin(self.probes["path"].values.astype(str), paths) | np.isin(labels, paths)
        return {name: self.probes[name].values[where] for name in self.probes.data_vars
                if self.probes[name].dims == ("probe",)}  # fmt: skip


_RUNS: dict[str, Run] = {}


def get_run(pattern: str, tmp_root: Path) -> Run:
    if pattern in _RUNS:
        return _RUNS[pattern]
    base = os.environ.get("DEM_VALIDATION_DIR")
    folder = Path(base) / f"default_{pattern}" if base else tmp_root / f"default_{pattern}"
    if not (folder / "summary.json").exists():
        from dem_taichi.protocol.runner import run_protocol

        run_protocol("default", folder, pattern=pattern, overwrite=True)
    _RUNS[pattern] = Run(folder)
    return _RUNS[pattern]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tmp_path_factory.mktemp("validation")


@pytest.mark.parametrize("pattern", PATTERNS)
def test_protocol_reaches_every_state_with_targets_held(pattern, root):
    run = get_run(pattern, root)
    states = run.summary["states"]
    for label in ("A", "B", "C", "B'"):
        assert label in states
    target = 100.0
    for label in ("B", "C", "B'"):
        assert abs(states[label]["mean_stress"] - target) <= TOL * target
    assert abs(states["B'"]["deviatoric_stress"]) <= 2 * TOL * target
    assert run.summary["transition"]["detector_agrees"]


# Where the DEM disagrees with the study (measured 2026-11-30 on `default` at commits 1fbc8c1
# (basic) and c3a67dc (acidic, neutral), same physics and servo; see
# benchmarks/results/protocol_validation_summary.md): the checks stay, marked as expected
# failures with the numbers, so that a change of the model that reproduces the study shows up as
# XPASS. Interaction fabrics from `python -m dem_taichi anisotropy` (contact share of the
# affine stiffness = 1.000 everywhere: k_n = 1e5 against k_a = 20).
_ISO_XFAIL = {
    "acidic": "measured: the 300-rod sample leaves the gas with rod fabric -0.093 at A (2.3 "
    "sigma) and isotropic compression raises it to -0.155 at B; E_h/E_v = 1.66 at A, 1.02-1.38 "
    "along A->B. At 1520 rods (paper scene) the same path stays within 0.009 and E_h/E_v = "
    "0.93-1.06",
    "basic": "measured: the fabric stays isotropic (max 0.035 < noise 0.041) but A is a marginal "
    "network (Z_m = 3.015) with E_h/E_v = 2.55 (linear response; 1.84 dynamic); 0.96-1.18 beyond",
}
# acidic passes the K0 check on the default seed (2), whose gas leaves A with rods already
# lying (-0.093) and ends at -0.233 (E_h/E_v 1.09 at C); seeds 11 and 12 (fabric at C -0.107,
# -0.149) give 0.87 at C, like the paper scene (0.84): E_h > E_v needs more rod alignment than
# K0 produces here against the contact anisotropy it builds.
_K0_XFAIL = {
    "basic": "measured: dense at A (v = 1.443), the rods barely rotate (-0.024 -> -0.059, "
    "< 3 noise); contact normals turn towards sigma_yy (+0.082, force-weighted +0.197 at C) "
    "and E_h/E_v = 0.78 -> 0.72 -> 0.80 -> 0.78 (affine contact estimate 0.83 at C)",
    "neutral": "measured: frictional rods jam at A (v = 1.461) and do not rotate (+0.048 -> "
    "+0.043); contact forces turn towards sigma_yy (force-weighted +0.141 at C) and E_h/E_v = "
    "0.94 -> 0.87 -> 0.82 -> 0.80",
}


def _with_xfail(reasons: dict[str, str]) -> list:
    return [
        pytest.param(p, marks=pytest.mark.xfail(strict=False, reason=reasons[p]))
        if p in reasons
        else p
        for p in PATTERNS
    ]


@pytest.mark.parametrize("pattern", _with_xfail(_ISO_XFAIL))
def test_isotropic_path_keeps_fabric_isotropic_and_moduli_equal(pattern, root):
    run = get_run(pattern, root)
    noise = fabric_sampling_noise(run.n_rods)
    iso = run.path("A_to_B")
    assert np.all(np.abs(iso["fabric_deviator"]) <= 3 * noise), iso["fabric_deviator"]
    rows = run.probe_rows(("A_to_B", "A"))
    ratio = rows["e_oed_h_linear"] / rows["e_oed_v_linear"]
    assert np.all(np.abs(ratio - 1.0) <= 0.15), ratio


@pytest.mark.parametrize("pattern", _with_xfail(_K0_XFAIL))
def test_k0_rods_lie_down_and_horizontal_stiffness_grows(pattern, root):
    run = get_run(pattern, root)
    noise = fabric_sampling_noise(run.n_rods)
    a = run.summary["states"]["A"]["fabric_deviator"]
    c = run.summary["states"]["C"]["fabric_deviator"]
    assert c < a - 3 * noise, (a, c)
    rows = run.probe_rows(("A_to_C",))
    order = np.argsort(rows["mean_stress"])
    ratio = (rows["e_oed_h_linear"] / rows["e_oed_v_linear"])[order]
    assert ratio[-1] > 1.0, ratio
    assert ratio[-1] > ratio[0], ratio


@pytest.mark.parametrize(
    "pattern",
    [
        "acidic",
        "basic",
        pytest.param(
            "neutral",
            marks=pytest.mark.xfail(
                strict=False,
                reason="measured: frictional rods without long-range forces jam at v = 1.461 "
                "and only compress elastically beyond A (lambda* = 0.0007, R2 = 0.77)",
            ),
        ),
    ],
)
def test_compressibility_linear_in_ln_v_ln_p_beyond_A(pattern, root):
    from dem_taichi.protocol.report import compressibility_slope

    run = get_run(pattern, root)
    iso = run.path("A_to_B")
    fit = compressibility_slope(iso["mean_stress"], iso["specific_volume"])
    assert fit["lambda_star"] > 0
    assert fit["r2"] >= 0.9, fit  # "roughly linear"


def test_acidic_looser_than_basic(root):
    acidic, basic = get_run("acidic", root), get_run("basic", root)
    for label in ("B", "C"):
        v_acidic = acidic.summary["states"][label]["specific_volume"]
        v_basic = basic.summary["states"][label]["specific_volume"]
        assert v_acidic > v_basic, (label, v_acidic, v_basic)


def get_paper_run(tmp_root: Path) -> Run:
    """The paper scene (1520 rods, acidic): ``DEM_VALIDATION_DIR/paper_acidic`` when it holds a
    run, else a new one with 2 workers (~20–40 min on 2 cores)."""
    if "paper" in _RUNS:
        return _RUNS["paper"]
    base = os.environ.get("DEM_VALIDATION_DIR")
    folder = Path(base) / "paper_acidic" if base else tmp_root / "paper_acidic"
    if not (folder / "summary.json").exists():
        from dem_taichi.protocol.runner import run_protocol

        run_protocol("paper", folder, workers=2, overwrite=True)
    _RUNS["paper"] = Run(folder)
    return _RUNS["paper"]


def test_paper_scene_findings_on_the_isotropic_path_and_k0_fabric(root):
    """At the study's size the sampling noise halves (sqrt(0.5/1520) = 0.018): the isotropic path
    keeps the fabric isotropic and E_h ≈ E_v (measured with the elastic servo: max |β_yy − β_xx|
    = 0.009, E_h/E_v 0.93–1.06), the rods lie down along K0 (0.000 → −0.173) and ln v – ln p is
    linear beyond A (R² = 0.95)."""
    from dem_taichi.protocol.report import compressibility_slope

    run = get_paper_run(root)
    noise = fabric_sampling_noise(run.n_rods)
    states = run.summary["states"]
    iso = run.path("A_to_B")
    assert np.all(np.abs(iso["fabric_deviator"]) <= 3 * noise), iso["fabric_deviator"]
    rows = run.probe_rows(("A_to_B", "A"))
    ratio = rows["e_oed_h_linear"] / rows["e_oed_v_linear"]
    assert np.all(np.abs(ratio - 1.0) <= 0.15), ratio
    assert states["C"]["fabric_deviator"] < states["A"]["fabric_deviator"] - 3 * noise
    fit = compressibility_slope(iso["mean_stress"], iso["specific_volume"])
    assert fit["r2"] >= 0.9, fit
    # the dynamic check of the linear response where the sweep ran (C)
    both = run.probe_rows(("C",))
    for name in ("e_oed_v", "e_oed_h"):
        lin, dyn = both[f"{name}_linear"], both[f"{name}_dynamic"]
        assert np.all(np.abs(dyn / lin - 1.0) <= 0.03), (name, lin, dyn)
