"""The demo script runs end to end in smoke mode and writes its files."""

import importlib.util
from pathlib import Path

import pytest
import xarray as xr

ROOT = Path(__file__).resolve().parents[2]


def test_demo_smoke(tmp_path):
    spec = importlib.util.spec_from_file_location("demo", ROOT / "scripts" / "demo.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    result = demo.run_tiv_demo(tmp_path, smoke=True)
    for path in list(result["files"].values()) + result["figures"] + [result["report"]]:
        assert path.exists() and path.stat().st_size > 0
    ds = xr.load_dataset(result["files"]["k0_unload"])
    assert ds.attrs["termination"] == "completed"
    summary = result["variants"]["A, constraint forces"]
    assert summary["plastic unloading increments"] == 0
    assert "| A, constraint forces |" in result["report"].read_text()


def load_demo():
    spec = importlib.util.spec_from_file_location("demo", ROOT / "scripts" / "demo.py")
    demo = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(demo)
    return demo


def test_demo_index_without_dem(tmp_path):
    assert load_demo().main(["--out", str(tmp_path), "--smoke", "--skip-dem"]) == 0
    index = (tmp_path / "REPORT.md").read_text()
    assert "skipped (--skip-dem)" in index and "tiv/tiv_report.md" in index


@pytest.mark.slow
def test_demo_whole_pipeline_on_the_smoke_scene(tmp_path):
    """DEM protocol -> calibration -> TIV element tests (about 2-3 minutes)."""
    assert load_demo().main(["--out", str(tmp_path), "--smoke"]) == 0
    index = (tmp_path / "REPORT.md").read_text()
    assert "calibration failed" not in index
    for name in ("dem/history.nc", "dem/probes.nc", "dem/report.md", "bridge/report.md"):
        assert (tmp_path / name).stat().st_size > 0, name


def test_the_report_opens_with_the_study_findings_beside_the_replicas_and_table1(tmp_path):
    """REPORT.md's first table: this run's value, the `study` scene's replicas (mean ± 95 % and
    the seed count, from the saved benchmark tables) and the study's value per finding."""
    from dem_taichi.analysis.findings import headline_findings
    from tests.dem_taichi.test_mapped_window import write_run

    demo = load_demo()
    run = write_run(tmp_path / "dem")
    dem = {"scene": "study_demo", "n_rods": 300, "findings": headline_findings(run),
           "k0_path": [(20.0, 1.1), (100.0, 1.4)], "seconds": 60.0, "states": {},
           "radial_paths": 0}  # fmt: skip
    reference = {"ratio_C": (1.47, 0.23, 3), "lambda_window": (0.150, 0.017, 3),
                 "stress_scale_kpa_measured": (0.971, 0.099, 3)}  # fmt: skip
    small = {"ratio_C": (1.66, 0.37, 3)}
    tiv = {
        "variants": {
            "A, constraint forces": {
                "K0 at 100 kPa": 0.66,
                "E_h/E_v at 100 kPa": 2.3,
                "fabric at 100 kPa": 0.13,
            }
        }
    }
    lines = demo.findings_lines(dem, tiv, {"300 rods": small, "1520 rods": reference})
    text = "\n".join(lines)
    assert lines[0] == "## The study's findings on this run"
    rows = {line.split(" | ")[0].lstrip("| "): line for line in lines if line.startswith("| ")}
    assert "| finding | this run | 300 rods | 1520 rods | the study |" in lines
    at_c = rows["E_h/E_v at C (K0, p = 100 kPa)"]
    assert "| 1.66 ± 0.37 (3 seeds) | 1.47 ± 0.23 (3 seeds) | > 1 |" in at_c
    assert at_c.startswith("| E_h/E_v at C (K0, p = 100 kPa) | — |")  # no K0 probe in the run
    window = rows["λ* over 1–200 kPa"]
    assert "| 0.25 (Table 1) |" in window  # the synthetic run's λ* is 0.25 too
    assert window.startswith("| λ* over 1–200 kPa | 0.25 | — | 0.15 ± 0.017 (3 seeds)")
    assert "0.660 (Table 1 model, σ_v = 100 kPa)" in rows["K0 at C"]
    assert "| 0.80 (n + r, Table 1) |" in rows["E_v ∝ p^n over 1–200 kPa"]
    assert "| 200 | — | 0.971 ± 0.099 (3 seeds) |" in rows["kPa per DEM unit (E_v/p = 125)"]
    overlap = rows["largest contact overlap δ/d, labelled states"]
    assert overlap.startswith("| largest contact overlap δ/d, labelled states | — |")  # no files
    assert overlap.endswith("| < 0.01 (issue 19's bar) |")
    assert "20: 1.100, 100: 1.400" in text and "E_h/E_v = 2.30 at σ_v = 100 kPa" in text
    assert "cannot determine the fabric law's c and s" in text
    # the saved tables of the repository give the replica columns when none are passed
    saved = {title: demo._reference(files) for title, files in demo.REFERENCES.items()}
    small, large = saved["`study_demo`, 300 rods"], saved["`study`, 1520 rods"]
    assert small["ratio_C"][2] == 3 and large["ratio_C"][2] == 7  # 3 and 7 seeds
    assert large["stress_scale_kpa_measured"][2] == 7  # the isotropic paths to 200 kPa
    assert large["max_overlap"][2] == 7 and small["max_overlap"][2] == 3
    assert small["ratio_C_minus_B"][0] > 0 and large["ratio_C_minus_B"][0] > 0
    index = demo.write_index(tmp_path, {"dem": dem, "bridge": "skipped", "tiv": {**tiv,
                             "report": tmp_path / "tiv" / "r.md"}})  # fmt: skip
    assert index.read_text().split("\n")[2] == "## The study's findings on this run"
