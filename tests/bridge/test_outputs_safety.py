"""The bridge's output folder (issue 22, bridge.outputs): an earlier calibration refused unless
--overwrite, which deletes exactly the files of its manifest (stale ones included), no writing
through links, no DEM run folder as --out, a full disk as exit code 4.

Each calibration is the quick synthetic one (compressibility stage, no figures, no profiles).
"""

from __future__ import annotations

import errno
import json
from pathlib import Path

from bridge.outputs import MANIFEST
from bridge.pipeline import calibrate_from_results, main, synthetic_inputs
from tests.sentinels import one_line, sentinel, survived

QUICK = ("--stages", "compressibility", "--no-figures", "--no-identifiability", "--passes", "1",
         "--quiet")  # fmt: skip


def calibrate(out: Path, *extra: str) -> int:
    return main(["--synthetic", "--out", str(out), *QUICK, *extra])


def listed(out: Path) -> list[str]:
    return json.loads((out / MANIFEST).read_text())["files"]


def test_the_manifest_lists_every_file_written(tmp_path):
    out = tmp_path / "cal"
    mine = sentinel(out / "notes.txt")
    assert calibrate(out) == 0
    written = {p.name for p in out.iterdir()} - {"notes.txt", MANIFEST}
    assert set(listed(out)) == written
    assert {"report.md", "calibration.json", "synthetic_probes.nc"} <= written
    assert survived(mine)


def test_an_earlier_calibration_is_refused_and_overwrite_removes_stale_files(tmp_path, capsys):
    out = tmp_path / "cal"
    assert calibrate(out) == 0
    # an earlier calibration had a radial path: its prediction is listed but not written again
    (out / "prediction_radial_1.nc").write_text("stale")
    manifest = json.loads((out / MANIFEST).read_text())
    manifest["files"].append("prediction_radial_1.nc")
    (out / MANIFEST).write_text(json.dumps(manifest))
    mine = sentinel(out / "prediction_mine.nc")  # a bridge name, not listed: kept
    outside = sentinel(tmp_path / "outside.txt")
    capsys.readouterr()
    assert calibrate(out) == 2
    line = one_line(capsys.readouterr().err)
    assert "already holds an earlier calibration" in line and "--overwrite" in line
    assert (out / "prediction_radial_1.nc").exists()
    assert calibrate(out, "--overwrite") == 0
    assert not (out / "prediction_radial_1.nc").exists()
    assert "prediction_radial_1.nc" not in listed(out)
    assert survived(mine, outside)


def test_the_python_call_removes_its_stale_files_but_never_its_inputs(tmp_path):
    out = tmp_path / "cal"
    history, probes, _ = synthetic_inputs(out)
    options = {"stages": ("compressibility",), "figures": False, "identifiability": False}
    calibrate_from_results(history, probes, out, options)
    (out / "prediction_radial_2.nc").write_text("stale")
    manifest = json.loads((out / MANIFEST).read_text())
    (out / MANIFEST).write_text(
        json.dumps(manifest | {"files": [*manifest["files"], "prediction_radial_2.nc"]})
    )
    calibrate_from_results(history, probes, out, options)
    assert not (out / "prediction_radial_2.nc").exists()
    assert history.exists() and probes.exists()


def test_a_manifest_naming_a_path_outside_is_refused(tmp_path, capsys):
    out = tmp_path / "cal"
    assert calibrate(out) == 0
    outside = sentinel(tmp_path / "outside.txt")
    manifest = json.loads((out / MANIFEST).read_text())
    manifest["files"].append("../outside.txt")
    (out / MANIFEST).write_text(json.dumps(manifest))
    capsys.readouterr()
    assert calibrate(out, "--overwrite") == 2
    assert "not a readable list" in one_line(capsys.readouterr().err)
    assert survived(outside)


def test_a_dem_run_folder_as_out_is_refused(tmp_path, capsys):
    run = tmp_path / "run"
    report = sentinel(run / "report.md")
    sentinel(run / "run.json")
    for extra in ((), ("--overwrite",)):
        assert calibrate(run, *extra) == 2
        line = one_line(capsys.readouterr().err)
        assert "is a DEM run folder" in line and str(run / "calibration") in line
    assert survived(report)


def test_a_link_where_the_bridge_writes_is_refused_and_its_target_unchanged(tmp_path, capsys):
    target = sentinel(tmp_path / "elsewhere" / "thesis.md")
    out = tmp_path / "cal"
    out.mkdir()
    (out / "report.md").symlink_to(target)
    for extra in ((), ("--overwrite",)):
        assert calibrate(out, *extra) == 2
        assert "report.md is a symbolic link" in one_line(capsys.readouterr().err)
    assert survived(target) and (out / "report.md").is_symlink()


def test_an_empty_out_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    here = sentinel(tmp_path / "report.md")
    assert main(["--synthetic", "--out", "", "--overwrite", *QUICK]) == 2
    assert "--out is empty" in one_line(capsys.readouterr().err)
    assert survived(here)


def test_overwrite_of_a_folder_without_a_manifest_is_refused(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    mine = [sentinel(tmp_path / "report.md"), sentinel(tmp_path / "calibration.json")]
    assert calibrate(Path("."), "--overwrite") == 2
    line = one_line(capsys.readouterr().err)
    assert "but no calibration_files.json" in line and "report.md" in line
    assert survived(*mine)


def test_a_full_disk_is_exit_code_4_with_one_line(tmp_path, monkeypatch, capsys):
    import bridge.pipeline as pipeline

    def no_space(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", "report.md")

    monkeypatch.setattr(pipeline, "write_report", no_space)
    out = tmp_path / "cal"
    assert calibrate(out) == 4
    line = one_line(capsys.readouterr().err)
    assert line.startswith("python -m bridge.pipeline: error: disk full: report.md")
    # what was written before the disk filled up is listed: --overwrite can remove it
    assert "prediction_k0.nc" in listed(out)
