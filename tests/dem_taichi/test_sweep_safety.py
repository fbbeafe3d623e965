"""Sweeps never delete outside their folder, refuse huge grids at once, stop cleanly on a
signal and serve no HTTP routes unless asked (issue 22).

The signal test runs the reduced smoke protocol of ``test_sweep.py`` (one member) and stops it
as soon as the member has started: ~15 s on this 2-core machine.
"""

from __future__ import annotations

import json
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest

from dem_taichi.sweep.client import _local_cluster, _plan
from dem_taichi.sweep.command import main
from dem_taichi.sweep.member import checked_member_dir, run_member, write_json
from dem_taichi.sweep.spec import (
    MAX_MEMBERS,
    Member,
    SweepError,
    SweepSpec,
    check_member_name,
    sweep_from_toml,
)

REDUCED = """
[sweep.set]
"protocol.path_increments" = 1
"protocol.run_unloading" = false
"protocol.radial_stress_ratios" = ""
"probing.dynamic" = false
"probing.states" = "A, B, C"
"probing.every_n_increments" = 0
"protocol.servo_stiffness" = "secant"
"""
SENTINEL = "SENTINEL.txt"


def one_member(name: str) -> str:
    return f'[sweep]\nscene = "smoke"\n[[sweep.members]]\nname = {json.dumps(name)}\n'


# -- names -------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name",
    ["..", ".", "", "a/b", "/abs", "a\\b", "../x", "x" * 121, "white space", "tab\tname", "é"],
    ids=["dotdot", "dot", "empty", "slash", "absolute", "backslash", "up", "long", "space",
         "tab", "non-ascii"],
)  # fmt: skip
def test_unsafe_member_names_are_refused_at_load(name):
    with pytest.raises(SweepError) as raised:
        sweep_from_toml(one_member(name))
    message = str(raised.value)
    assert message.startswith("[[sweep.members]] #1 name = ")
    assert "A-Z a-z 0-9 - _ . = +" in message and "not '.' or '..'" in message
    assert "\n" not in message


@pytest.mark.parametrize("name", ["seed-1", "k_t=2e4", "a+b", ".hidden", "x" * 120, "..."])
def test_safe_member_names_are_kept(name):
    assert check_member_name(name, "m") == name


def test_a_generated_name_too_long_is_refused_naming_the_member():
    values = ", ".join(f'"{"v" * 120}{i}"' for i in range(2))
    text = f'[sweep]\nscene = "smoke"\n[sweep.grid]\n"scene.description" = [{values}]\n'
    with pytest.raises(SweepError, match=r"member \(scene.description = 'v{120}0'\): name"):
        sweep_from_toml(text)


# -- nothing outside the sweep folder is ever deleted -----------------------------------------
def failed_record(folder: Path, member: Member) -> None:
    write_json(folder / "member.json", {"status": "failed", "error": "ProtocolError: x",
                                        "scene_sha256": member.scene_sha256})  # fmt: skip


def test_the_dotdot_member_of_the_issue_is_refused_before_anything_is_deleted(tmp_path):
    """The issue's case: a member named ``..`` whose first run failed left ``member.json`` in
    the sweep folder itself; the re-run deleted the whole --out. Now the name is refused by the
    command line, and the functions that delete refuse it too when given it directly."""
    out = tmp_path / "sweep"
    out.mkdir()
    (out / SENTINEL).write_text("keep me")
    good = sweep_from_toml(one_member("fine")).members[0]
    dotdot = Member("..", good.overrides, good.parameters, good.scene_toml)
    failed_record(out, dotdot)  # what the first run wrote to members/../member.json
    (tmp_path / "s.toml").write_text(one_member(".."))
    assert main([str(tmp_path / "s.toml"), "--out", str(out)]) == 2
    spec = SweepSpec(name="s", scene="smoke", members=(dotdot,))
    with pytest.raises(SweepError, match="name = '..'"):
        _plan(spec, out, overwrite=False)
    with pytest.raises(SweepError, match="name = '..'"):
        run_member("..", dotdot.scene_toml, str(out / "members" / ".."), sweep_dir=str(out))
    with pytest.raises(SweepError):
        run_member("..", dotdot.scene_toml, str(out / "members" / ".."))
    assert (out / SENTINEL).read_text() == "keep me"


def test_a_member_folder_linked_elsewhere_is_never_deleted(tmp_path):
    out, elsewhere = tmp_path / "sweep", tmp_path / "precious"
    elsewhere.mkdir()
    (elsewhere / SENTINEL).write_text("keep me")
    member = sweep_from_toml(one_member("m1")).members[0]
    failed_record(elsewhere, member)
    (out / "members").mkdir(parents=True)
    (out / "members" / "m1").symlink_to(elsewhere, target_is_directory=True)
    spec = SweepSpec(name="s", scene="smoke", members=(member,))
    with pytest.raises(SweepError, match="resolves to .*precious.*symbolic link"):
        _plan(spec, out, overwrite=False)
    with pytest.raises(SweepError, match="resolves to"):
        run_member("m1", member.scene_toml, str(out / "members" / "m1"), sweep_dir=str(out))
    with pytest.raises(SweepError, match="not .*members/m1"):
        run_member("m1", member.scene_toml, str(elsewhere))  # not in a members folder
    assert (elsewhere / SENTINEL).read_text() == "keep me"
    assert json.loads((elsewhere / "member.json").read_text())["status"] == "failed"


def test_a_linked_members_folder_is_refused(tmp_path):
    out, elsewhere = tmp_path / "sweep", tmp_path / "other"
    (elsewhere / "m1").mkdir(parents=True)
    (elsewhere / "m1" / SENTINEL).write_text("keep me")
    out.mkdir()
    (out / "members").symlink_to(elsewhere, target_is_directory=True)
    with pytest.raises(SweepError, match="not inside the sweep folder"):
        checked_member_dir(out, "m1")
    assert (elsewhere / "m1" / SENTINEL).exists()


def failed_run(tmp_path: Path) -> tuple[Path, Member]:
    """A member folder whose first run failed: a run record listing history.nc and a
    checkpoint, and the user's SENTINEL beside them (not in the manifest)."""
    from dem_taichi.io.run_directory import start_run

    member = sweep_from_toml(one_member("m1")).members[0]
    folder = tmp_path / "sweep" / "members" / "m1"
    with start_run(folder, "protocol", "smoke", member.scene_toml) as run:
        run.output("history.nc").write_text("old run")
        (folder / "checkpoints").mkdir()
        run.output("checkpoints/checkpoint_000000000100.npz").write_text("old run")
    failed_record(folder, member)
    (folder / SENTINEL).write_text("keep me")
    return folder, member


def fake_protocol(seen: list):
    """A stand-in for run_protocol that notes what the member folder holds when it starts."""

    class Result:
        states = {"A": None}

    def run_protocol(scene, out, **kwargs):
        seen.append(sorted(str(p.relative_to(out)) for p in Path(out).rglob("*")))
        return Result()

    return run_protocol


def test_a_failed_member_is_cleared_by_its_manifest_under_its_lock(tmp_path, monkeypatch):
    """Issue 22: the re-run of a failed member deleted its whole folder (shutil.rmtree); now
    the files its run.json lists go (with the folder's lock held) and the user's file stays."""
    folder, member = failed_run(tmp_path)
    seen: list = []
    monkeypatch.setattr("dem_taichi.protocol.runner.run_protocol", fake_protocol(seen))
    record = run_member("m1", member.scene_toml, str(folder), sweep_dir=str(tmp_path / "sweep"))
    assert record["status"] == "done", record
    assert (folder / SENTINEL).read_text() == "keep me"
    assert seen == [[SENTINEL, "member.json", "progress.log"]]
    assert not (folder / "run.lock").exists()


def test_a_member_folder_locked_by_a_live_process_is_skipped_untouched(
    tmp_path, monkeypatch, capsys
):
    folder, member = failed_run(tmp_path)
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock = {"pid": live.pid, "host": socket.gethostname(), "started": "now",
                "command": "protocol", "token": "other"}  # fmt: skip
        (folder / "run.lock").write_text(json.dumps(lock))
        before = sorted(p.name for p in folder.rglob("*"))
        seen: list = []
        monkeypatch.setattr("dem_taichi.protocol.runner.run_protocol", fake_protocol(seen))
        record = run_member("m1", member.scene_toml, str(folder), sweep_dir=str(tmp_path / "sweep"))
    finally:
        live.kill()
        live.wait()
    assert record["status"] == "skipped" and seen == []
    assert sorted(p.name for p in folder.rglob("*")) == before
    assert json.loads((folder / "member.json").read_text())["status"] == "failed"
    assert json.loads((folder / "run.lock").read_text())["pid"] == live.pid
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "member m1: skipped" in err[0] and str(live.pid) in err[0], err


# -- the summary's files ---------------------------------------------------------------------
def finished_sweep(tmp_path: Path) -> Path:
    """A sweep folder with two finished members (the synthetic runs of test_mapped_window)."""
    from .test_mapped_window import write_run

    out = tmp_path / "sweep"
    members = []
    for seed in (1, 2):
        name = f"seed-{seed}"
        write_run(out / "members" / name)
        write_json(out / "members" / name / "member.json", {"status": "done", "scene_sha256": "x"})
        members.append({"name": name, "parameters": {"scene.seed": seed}, "scene_sha256": "x"})
    write_json(out / "sweep.json", {"sweep": "s", "scene": "smoke", "members": members})
    return out


def test_summarise_refuses_existing_files_unless_overwrite(tmp_path, capsys):
    """Issue 22: ``summarise --out FILE`` replaced an existing file silently."""
    out = finished_sweep(tmp_path)
    table = tmp_path / "mine.md"
    table.write_text("the user's notes")
    capsys.readouterr()
    assert main(["summarise", str(out), "--out", str(table), "--quiet"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and str(table) in err[0] and "--overwrite" in err[0], err
    assert table.read_text() == "the user's notes" and not (tmp_path / "mine.png").exists()
    assert main(["summarise", str(out), "--out", str(table), "--quiet", "--overwrite"]) == 0
    assert "λ*" in table.read_text()
    for name in ("mine.png", "mine.json", "mine_members.nc"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporaries
    # the default table in the sweep folder: written once, then refused
    assert main(["summarise", str(out), "--quiet"]) == 0
    assert main(["summarise", str(out), "--quiet"]) == 2
    assert "replica_summary.md" in capsys.readouterr().err


def test_summarise_never_writes_through_a_link(tmp_path, capsys):
    out = finished_sweep(tmp_path)
    precious = tmp_path / "precious.json"
    precious.write_text("keep me")
    (tmp_path / "mine.json").symlink_to(precious)  # where the statistics go
    argv = ["summarise", str(out), "--out", str(tmp_path / "mine.md"), "--quiet"]
    assert main(argv) == 2
    assert "mine.json" in capsys.readouterr().err and precious.read_text() == "keep me"
    assert main([*argv, "--overwrite"]) == 0
    assert precious.read_text() == "keep me" and not (tmp_path / "mine.json").is_symlink()
    assert "all members" in (tmp_path / "mine.json").read_text()


def test_summarise_refuses_an_out_that_names_its_companions(tmp_path, capsys):
    out = finished_sweep(tmp_path)
    assert main(["summarise", str(out), "--out", str(tmp_path / "table.png"), "--quiet"]) == 2
    assert "give a markdown file" in capsys.readouterr().err


# -- size ----------------------------------------------------------------------------------------
def test_a_grid_of_a_hundred_million_members_is_refused_at_once(tmp_path, capsys):
    values = "[" + ", ".join(str(i) for i in range(100)) + "]"
    floats = "[" + ", ".join(f"0.{i:03d}" for i in range(1, 101)) + "]"
    text = (
        f'[sweep]\nscene = "smoke"\n[sweep.grid]\n"scene.seed" = {values}\n'
        f'"contact.mu" = {floats}\n"particles.n_rods" = {values.replace("[0, ", "[100, ")}\n'
        f'"output.every" = {values.replace("[0, ", "[100, ")}\n'
    )
    start = time.perf_counter()
    with pytest.raises(SweepError) as raised:
        sweep_from_toml(text)
    assert time.perf_counter() - start < 2.0
    assert "makes 100,000,000 members (100 × 100 × 100 × 100)" in str(raised.value)
    assert f"allowed at most {MAX_MEMBERS:,}" in str(raised.value)
    (tmp_path / "big.toml").write_text(text)
    start = time.perf_counter()
    assert main([str(tmp_path / "big.toml"), "--out", str(tmp_path / "o")]) == 2
    assert time.perf_counter() - start < 2.0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "100,000,000 members" in err[0] and "--max-members" in err[0]
    assert not (tmp_path / "o").exists()


def test_the_member_limit_counts_listed_members_and_can_be_raised():
    text = '[sweep]\nscene = "smoke"\n[sweep.grid]\n"scene.seed" = [1, 2, 3]\n' + "".join(
        f'[[sweep.members]]\nname = "m{i}"\n' for i in range(2)
    )
    with pytest.raises(SweepError, match=r"makes 6 members \(3 × 2 \[\[sweep.members\]\]\)"):
        sweep_from_toml(text, max_members=5)
    assert len(sweep_from_toml(text, max_members=6).members) == 6


# -- signals -------------------------------------------------------------------------------------
def start_sweep(sweep_file: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "dem_taichi.sweep", str(sweep_file), "--out", str(out),
         "--n-workers", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=sweep_file.parent,
    )  # fmt: skip


def wait_for_line(process: subprocess.Popen, words: str, timeout: float = 120.0) -> list[str]:
    """stdout lines up to the first holding ``words`` (fails on exit or timeout)."""
    lines, deadline = [], time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            pytest.fail(f"sweep exited before {words!r}: {lines} {process.stderr.read()}")
        lines.append(line.rstrip("\n"))
        if words in line:
            return lines
    pytest.fail(f"no {words!r} in {timeout} s: {lines}")


def test_sigterm_prints_one_line_and_the_rerun_resumes(tmp_path):
    sweep_file, out = tmp_path / "one.toml", tmp_path / "sweep"
    sweep_file.write_text(
        '[sweep]\nname = "one"\nscene = "smoke"\n' + REDUCED + '[sweep.grid]\n"scene.seed" = [1]\n'
    )
    first = start_sweep(sweep_file, out)
    try:
        wait_for_line(first, "seed-1: started")
        first.send_signal(signal.SIGTERM)
        _, err = first.communicate(timeout=60)
    finally:
        first.kill()
    assert first.returncode == 128 + signal.SIGTERM, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("python -m dem_taichi.sweep: SIGTERM: stopped; 0 of 1 members")
    assert "the same command resumes the other 1: python -m dem_taichi.sweep" in lines[0]
    record = json.loads((out / "members" / "seed-1" / "member.json").read_text())
    assert record["status"] == "running"  # left for the re-run, not marked done or deleted

    again = start_sweep(sweep_file, out)
    try:
        said = wait_for_line(again, "seed-1: ")
        again.send_signal(signal.SIGTERM)  # stopped again, while its cluster starts
        _, err = again.communicate(timeout=60)
    finally:
        again.kill()
    assert said[0] == (
        "sweep one: resuming: 0 of 1 members done before (skipped), 1 to run (1 unfinished, "
        "0 failed, 0 changed, 0 not started)"
    )
    assert said[1].startswith("  seed-1: unfinished; ")
    assert ("resumes from its saved state A" in said[1]) or ("runs again from the gas" in said[1])
    assert "from scratch" not in "\n".join(said)
    assert again.returncode == 128 + signal.SIGTERM and len(err.strip().splitlines()) == 1


# -- no dashboard --------------------------------------------------------------------------------
def http_status(port: int, path: str) -> int | str:
    try:
        return urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5).status
    except urllib.error.HTTPError as error:
        return error.code
    except OSError as error:
        return type(error).__name__


def port_8787_taken() -> bool:
    with socket.socket() as probe:
        return probe.connect_ex(("127.0.0.1", 8787)) == 0


def test_the_local_cluster_serves_no_dashboard_unless_asked():
    from distributed import Client

    taken_before = port_8787_taken()
    cluster = _local_cluster(1, None)
    try:
        http = cluster.scheduler.http_server.port
        assert http != 8787
        if not taken_before:
            assert not port_8787_taken()
        for path in ("/status", "/json/identity.json", "/info/main/workers.html", "/health"):
            assert http_status(http, path) == 404, path
        with Client(cluster) as client:
            (worker,) = client.scheduler_info()["workers"].values()
            assert http_status(worker["services"]["dashboard"], "/metrics") == 404
    finally:
        cluster.close()
    asked = _local_cluster(0, "127.0.0.1:0")
    try:
        assert http_status(asked.scheduler.http_server.port, "/status") == 200
    finally:
        asked.close()


# -- the scheduler's TLS options -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--scheduler", "tls://h:8786"], "--scheduler tls://h:8786 is a TLS address"),
        (["--tls-ca-file", "ca.pem"], "apply to --scheduler only"),
        (["--scheduler", "tls://h:8786", "--tls-cert", "c.pem"], "need --tls-ca-file"),
        (["--scheduler", "tls://h:8786", "--tls-ca-file", "none.pem", "--tls-cert", "c.pem"],
         "--tls-ca-file none.pem: no such file"),
        (["--scheduler", "tcp://h:8786", "--tls-ca-file", "c.pem", "--tls-cert", "c.pem"],
         "must start with tls://"),
        (["--scheduler", "tcp://h:8786\nx"], "control character"),
        (["--max-members", "0"], "--max-members"),
    ],
)  # fmt: skip
def test_scheduler_options_are_checked_before_anything_runs(
    extra, words, tmp_path, capsys, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "c.pem").write_text("not read before the checks")
    (tmp_path / "s.toml").write_text(one_member("m1"))
    assert main(["s.toml", "--out", "o", *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and words in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_sweep_record_naming_dotdot_is_refused_when_read(tmp_path):
    from dem_taichi.sweep.results import open_sweep

    (tmp_path / "members").mkdir()
    write_json(tmp_path / "sweep.json", {"sweep": "s", "scene": "smoke", "members": [
        {"name": "..", "parameters": {}, "overrides": {}, "scene_sha256": "x"}]})  # fmt: skip
    with pytest.raises(SweepError, match="name = '..'"):
        open_sweep(tmp_path)


def make_certificates(folder: Path) -> None:
    """A CA signing a scheduler and a client certificate, and another CA signing a stranger's
    (EC keys, for 127.0.0.1; one day)."""
    key = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]

    def openssl(*args: str) -> None:
        subprocess.run(["openssl", *args], cwd=folder, check=True, capture_output=True)

    for ca in ("ca", "other_ca"):
        openssl("req", "-x509", *key, "-keyout", f"{ca}.key", "-out", f"{ca}.pem", "-days", "1",
                "-subj", f"/CN={ca}")  # fmt: skip
    (folder / "san.ext").write_text("subjectAltName=IP:127.0.0.1,DNS:localhost\n")
    for who, ca in (("scheduler", "ca"), ("client", "ca"), ("stranger", "other_ca")):
        openssl("req", *key, "-keyout", f"{who}.key", "-out", f"{who}.csr", "-subj", f"/CN={who}")
        openssl(
            "x509",
            "-req",
            "-in",
            f"{who}.csr",
            "-CA",
            f"{ca}.pem",
            "-CAkey",
            f"{ca}.key",
            "-CAcreateserial",
            "-out",
            f"{who}.pem",
            "-days",
            "1",
            "-extfile",
            "san.ext",
        )


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl command")
def test_tls_options_connect_only_with_a_certificate_of_the_ca(tmp_path):
    """A TLS scheduler that requires encryption: the sweep's --tls-* options connect; plain
    TCP and a certificate signed by another CA are refused."""
    import argparse

    from distributed import Client, LocalCluster
    from distributed.security import Security

    from dem_taichi.sweep.client import _cluster
    from dem_taichi.sweep.command import _security

    make_certificates(tmp_path)
    files = {name: str(tmp_path / name) for name in (
        "ca.pem", "scheduler.pem", "scheduler.key", "client.pem", "client.key", "stranger.pem",
        "stranger.key")}  # fmt: skip
    server = Security(
        tls_ca_file=files["ca.pem"], require_encryption=True,
        tls_scheduler_cert=files["scheduler.pem"], tls_scheduler_key=files["scheduler.key"],
        tls_client_cert=files["scheduler.pem"], tls_client_key=files["scheduler.key"],
    )  # fmt: skip
    spec = sweep_from_toml(one_member("m1"))
    with LocalCluster(n_workers=0, protocol="tls://", host="127.0.0.1", security=server,
                      dashboard_address=None) as cluster:  # fmt: skip
        address = cluster.scheduler_address
        args = argparse.Namespace(
            scheduler=address,
            tls_ca_file=files["ca.pem"],
            tls_cert=files["client.pem"],
            tls_key=files["client.key"],
        )
        client, local, where = _cluster(address, None, spec, 1, security=_security(args))
        try:
            assert local is None and where == f"scheduler {address} (TLS)"
            assert client.scheduler_info()["address"] == address
        finally:
            client.close()
        with pytest.raises(OSError):
            Client(address.replace("tls://", "tcp://"), timeout="3s")
        stranger = Security(
            tls_ca_file=files["ca.pem"],
            tls_client_cert=files["stranger.pem"],
            tls_client_key=files["stranger.key"],
            require_encryption=True,
        )
        with pytest.raises(OSError):
            Client(address, security=stranger, timeout="3s")
