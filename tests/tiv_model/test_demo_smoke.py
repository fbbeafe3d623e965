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
