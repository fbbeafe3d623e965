"""The demo script runs end to end in smoke mode and writes its files."""

import importlib.util
from pathlib import Path

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
