"""Bad inputs across the command lines (issue 11): each is refused with its exit code, one line
on stderr naming what is wrong (the words checked), and no traceback.

Entry points: ``python -m dem_taichi run|protocol`` (:func:`dem_taichi.cli.commands.main`),
``python -m dem_taichi.protocol``, ``python -m dem_taichi.sweep``, ``python -m tiv_model`` and
``python -m bridge.pipeline``, called in process (their ``main`` returns the exit code) and, for
a few, as real processes. ``ISSUE22_CASES`` (issue 22) were accepted, or blamed on the wrong key,
before: a ``--set`` with a line break, numbers that overflow (any scene key beyond 1e±12, TIV
parameters beyond 1e8), k_t beyond what the time step resolves, non-UTF-8 files, unsafe sweep
member names, wrongly shaped netCDF given to the bridge.
"""

from __future__ import annotations

import functools
import math
import subprocess
import sys
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from dem_taichi.scene.config import load_scene, scene_to_toml

ROOT = Path(__file__).resolve().parents[1]
SMOKE = tomllib.loads(scene_to_toml(load_scene("smoke")))


def toml_text(data: dict) -> str:
    def value(v):
        if isinstance(v, bool):
            return "true" if v else "false"
        return f'"{v}"' if isinstance(v, str) else repr(v)

    lines = []
    for section, table in data.items():
        if not isinstance(table, dict):
            lines.append(f"{section} = {value(table)}")
            continue
        lines.append(f"[{section}]")
        lines += [f"{k} = {value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def smoke_with(**changes) -> str:
    """The smoke scene as TOML with ``section={"key": value}`` changes (None deletes a key)."""
    data = {name: dict(table) for name, table in SMOKE.items()}
    for section, keys in changes.items():
        if not isinstance(keys, dict):
            data[section] = keys
            continue
        table = data.setdefault(section, {})
        for key, v in keys.items():
            table.pop(key) if v is None else table.__setitem__(key, v)
    return toml_text(data)


@dataclass(frozen=True)
class Case:
    id: str
    entry: str  # dem | protocol | tiv | bridge | sweep | anisotropy
    argv: tuple[str, ...]
    words: tuple[str, ...]
    scene: str | None = None  # written to {scene}
    setup: Callable[[Path], None] | None = field(default=None, compare=False)
    code: int = 2


def used_directory(tmp: Path) -> None:
    (tmp / "out").mkdir()
    (tmp / "out" / "history.nc").write_text("an earlier run")


def a_file_as_out(tmp: Path) -> None:
    (tmp / "out").write_text("not a folder")


def a_run_of_another_scene(tmp: Path) -> None:
    from dem_taichi.io.checkpoint import checkpoint_path, save_checkpoint
    from dem_taichi.io.run_directory import start_run

    other = scene_to_toml(load_scene("smoke").replace(scene={"seed": 9}))
    run = start_run(tmp / "out", "run", "smoke", other)
    path = checkpoint_path(run.checkpoint_dir, 500)
    run.add_checkpoint(save_checkpoint(path, {"angle": np.zeros(1)}, {"scene_toml": other}))


def a_folder(tmp: Path) -> None:
    (tmp / "folder").mkdir()


def text_files(tmp: Path) -> None:
    (tmp / "notes.txt").write_text("not netCDF")


def wrong_netcdf(tmp: Path) -> None:
    xr.Dataset({"x": ("time", np.arange(3.0))}).to_netcdf(tmp / "wrong.nc")


def synthetic_files(tmp: Path, name: str = "", **attrs) -> None:
    """Small synthetic DEM results (history.nc, probes.nc) with ``attrs`` on variable ``name``
    (None: attribute removed); for the units the bridge reads (issue 11)."""
    from bridge.series import Convention
    from bridge.synthetic import synthetic_results
    from tiv_model.params import TABLE1

    data = synthetic_results(
        TABLE1, convention=Convention(50.0), increments=2, unloading_increments=1
    )
    for ds, kind in ((data.history, "history"), (data.probes, "probes")):
        if name in ds.variables:
            ds[name].attrs.update({k: v for k, v in attrs.items() if v is not None})
            for key in (k for k, v in attrs.items() if v is None):
                ds[name].attrs.pop(key, None)
        ds.to_netcdf(tmp / f"{kind}.nc")


def stress_in_metres(tmp: Path) -> None:
    synthetic_files(tmp, "stress_yy", units="m", dem_units=None)


def modulus_in_kilograms(tmp: Path) -> None:
    synthetic_files(tmp, "e_oed_v_linear", units="kg", dem_units=None)


def stress_without_units(tmp: Path) -> None:
    synthetic_files(tmp, "stress_xx", units=None)


def not_utf8_scene(tmp: Path) -> None:
    """The smoke scene saved in Latin-1 with an accented description (issue 22)."""
    text = smoke_with(scene={"description": "argile très molle"})
    (tmp / "scene.toml").write_bytes(text.encode("latin-1"))


def binary_scene(tmp: Path) -> None:
    (tmp / "scene.toml").write_bytes(b"\xff\xfe[\x00p\x00a\x00r\x00t\x00]\x00")


def history_variant(tmp: Path, change) -> None:
    """Synthetic history.nc and probes.nc with ``change(history, probes)`` applied."""
    from bridge.series import Convention
    from bridge.synthetic import synthetic_results
    from tiv_model.params import TABLE1

    data = synthetic_results(
        TABLE1, convention=Convention(50.0), increments=2, unloading_increments=1
    )
    history, probes = change(data.history.copy(), data.probes.copy())
    history.to_netcdf(tmp / "history.nc")
    probes.to_netcdf(tmp / "probes.nc")


def stress_2d(tmp: Path) -> None:
    def change(h, p):
        h["stress_xx"] = (("time", "x"), np.stack([h["stress_xx"].values] * 2, 1),
                          h["stress_xx"].attrs)  # fmt: skip
        return h, p

    history_variant(tmp, change)


def stress_scalar(tmp: Path) -> None:
    def change(h, p):
        h["stress_yy"] = ((), 1.0, h["stress_yy"].attrs)
        return h, p

    history_variant(tmp, change)


def history_empty(tmp: Path) -> None:
    history_variant(tmp, lambda h, p: (h.isel(time=slice(0, 0)), p))


def stress_as_text(tmp: Path) -> None:
    def change(h, p):
        h["specific_volume"] = h["specific_volume"].astype(str)
        return h, p

    history_variant(tmp, change)


def volume_on_another_dimension(tmp: Path) -> None:
    def change(h, p):
        h["specific_volume"] = (("record",), h["specific_volume"].values,
                                h["specific_volume"].attrs)  # fmt: skip
        return h, p

    history_variant(tmp, change)


def tensor_flat(tmp: Path) -> None:
    def change(h, p):
        tensor = p["stiffness_tensor_linear"]
        p["stiffness_tensor_linear"] = (("probe",), np.ones(p.sizes["probe"]), tensor.attrs)
        return h, p

    history_variant(tmp, change)


def probe_moduli_2d(tmp: Path) -> None:
    def change(h, p):
        modulus = p["e_oed_v_linear"]
        p["e_oed_v_linear"] = (("probe", "y"), np.stack([modulus.values] * 3, 1), modulus.attrs)
        return h, p

    history_variant(tmp, change)


def sweep_file(text: str, scene: bytes | None = None):
    """A setup writing ``sweep.toml`` (and ``base.toml``, bytes, when given)."""

    def setup(tmp: Path) -> None:
        (tmp / "sweep.toml").write_text(text)
        if scene is not None:
            (tmp / "base.toml").write_bytes(scene)

    return setup


def sweep_bytes(data: bytes):
    def setup(tmp: Path) -> None:
        (tmp / "sweep.toml").write_bytes(data)

    return setup


# the tables: one case a line
# fmt: off
RUN = ("run", "{scene}", "--out", "{out}")
PROTOCOL = ("protocol", "{scene}", "--out", "{out}")

DEM_CASES = [
    Case("run-steps-negative", "dem", (*RUN, "--steps", "-5"), ("--steps", "-5 is out of range", ">= 0"), smoke_with()),  # noqa: E501
    Case("run-steps-text", "dem", (*RUN, "--steps", "many"), ("--steps", "not an integer"), smoke_with()),  # noqa: E501
    Case("run-arch", "dem", (*RUN, "--arch", "tpu"), ("--arch", "invalid choice", "cpu"), smoke_with()),  # noqa: E501
    Case("run-precision", "dem", (*RUN, "--precision", "f16"), ("--precision", "f64"), smoke_with()),  # noqa: E501
    Case("run-no-out", "dem", ("run", "smoke"), ("required", "--out")),
    Case("run-no-scene", "dem", ("run",), ("required", "scene")),
    Case("run-unknown-option", "dem", (*RUN, "--fast"), ("unrecognized arguments", "--fast"), smoke_with()),  # noqa: E501
    Case("no-command", "dem", (), ("required", "command")),
    Case("unknown-command", "dem", ("simulate", "smoke"), ("invalid choice", "run", "protocol")),
    Case("scene-missing-file", "dem", ("run", "nothere.toml", "--out", "{out}"), ("nothere.toml", "does not exist", "built-in")),  # noqa: E501
    Case("scene-unknown-builtin", "dem", ("run", "smok", "--out", "{out}"), ("no built-in scene 'smok'", "smoke")),  # noqa: E501
    Case("scene-directory", "dem", ("run", "folder", "--out", "{out}"), ("is a directory",), setup=a_folder),  # noqa: E501
    Case("scene-empty", "dem", RUN, ("is empty", "[particles]", "built-in scene"), ""),
    Case("scene-comments-only", "dem", RUN, ("has no [particles] section",), "# nothing here\n"),
    Case("scene-no-particles", "dem", RUN, ("has no [particles] section", "n_rods"), "[contact]\nk_n = 1e5\n"),  # noqa: E501
    Case("scene-invalid-toml", "dem", RUN, ("invalid TOML",), "[particles\nn_rods = 4\n"),
    Case("scene-unknown-section", "dem", RUN, ("unknown section(s) [partikles]", "allowed sections"), smoke_with(partikles={"n_rods": 4})),  # noqa: E501
    Case("scene-unknown-key", "dem", RUN, ("[particles] unknown key(s) n_rod", "allowed keys"), smoke_with(particles={"n_rod": 4})),  # noqa: E501
    Case("scene-section-not-table", "dem", RUN, ("[particles] must be a table",), "particles = 3\n"),  # noqa: E501
    Case("scene-k_n-zero", "dem", RUN, ("[contact] k_n = 0.0 is out of range", "(0.0, inf)"), smoke_with(contact={"k_n": 0.0})),  # noqa: E501
    Case("scene-n_rods-zero", "dem", RUN, ("[particles] n_rods = 0 is out of range",), smoke_with(particles={"n_rods": 0})),  # noqa: E501
    Case("scene-n_rods-huge", "dem", RUN, ("n_rods", "out of range", "10000000"), smoke_with(particles={"n_rods": 10**9})),  # noqa: E501
    Case("scene-n_rods-text", "dem", RUN, ("[particles] n_rods = 'forty'", "integer"), smoke_with(particles={"n_rods": "forty"})),  # noqa: E501
    Case("scene-n_rods-float", "dem", RUN, ("n_rods = 40.5", "integer"), smoke_with(particles={"n_rods": 40.5})),  # noqa: E501
    Case("scene-friction-text", "dem", RUN, ("[contact] friction", "true or false"), smoke_with(contact={"friction": "yes"})),  # noqa: E501
    Case("scene-mu-negative", "dem", RUN, ("[contact] mu = -0.1 is out of range",), smoke_with(contact={"mu": -0.1})),  # noqa: E501
    Case("scene-e_n-and-gamma_n", "dem", RUN, ("either e_n or gamma_n",), smoke_with(contact={"gamma_n": 1.0})),  # noqa: E501
    Case("scene-e_n-above-one", "dem", RUN, ("[contact] e_n = 1.5 is out of range",), smoke_with(contact={"e_n": 1.5})),  # noqa: E501
    Case("scene-overdamped", "dem", RUN, ("overdamped",), smoke_with(contact={"e_n": None, "gamma_n": 1e4})),  # noqa: E501
    Case("scene-spacing", "dem", RUN, ("spacing = 1.5 > diameter", "touch"), smoke_with(particles={"spacing": 1.5})),  # noqa: E501
    Case("scene-pattern", "dem", RUN, ("[long_range] pattern = 'salty'", "acidic | basic | neutral"), smoke_with(long_range={"pattern": "salty"})),  # noqa: E501
    Case("scene-acidic-two-discs", "dem", RUN, ("acidic", "n_spheres >= 3"), smoke_with(particles={"n_spheres": 2})),  # noqa: E501
    Case("scene-area-fraction", "dem", RUN, ("initial_area_fraction = 0.6 is out of range",), smoke_with(particles={"initial_area_fraction": 0.6})),  # noqa: E501
    Case("scene-seed-negative", "dem", RUN, ("[scene] seed = -1 is out of range",), smoke_with(scene={"seed": -1})),  # noqa: E501
    Case("scene-rod-model", "dem", RUN, ("rod_model = 'floppy'", "rigid | bonded"), smoke_with(particles={"rod_model": "floppy"})),  # noqa: E501
    Case("scene-bonds-with-rigid", "dem", RUN, ("[bonds] is used only with", "rod_model = 'bonded'"), smoke_with(bonds={"bending": 0.3})),  # noqa: E501
    Case("scene-bonded-one-disc", "dem", RUN, ("needs n_spheres >= 2",), smoke_with(particles={"rod_model": "bonded", "n_spheres": 1}, long_range={"enabled": False})),  # noqa: E501
    Case("scene-bonded-dt", "dem", RUN, ("dt_safety = 0.45", "stability limit"), smoke_with(particles={"rod_model": "bonded"}, integration={"dt_safety": 0.45})),  # noqa: E501
    Case("scene-dt_safety-range", "dem", RUN, ("[integration] dt_safety = 0.9 is out of range",), smoke_with(integration={"dt_safety": 0.9})),  # noqa: E501
    Case("scene-execution", "dem", RUN, ("execution = 'fastest'", "serial"), smoke_with(integration={"execution": "fastest"})),  # noqa: E501
    Case("scene-every-zero", "dem", RUN, ("[output] every = 0 is out of range",), smoke_with(output={"every": 0})),  # noqa: E501
    Case("run-target-volume-above-gas", "dem", RUN, ("target_specific_volume = 9", "would not compress"), smoke_with(control={"target_specific_volume": 9.0})),  # noqa: E501
    Case("run-cell-too-small", "dem", RUN, ("n_rods = 1", "cell of side", "more rods"), smoke_with(particles={"n_rods": 1})),  # noqa: E501
    Case("run-used-directory", "dem", RUN, ("already holds", "--overwrite", "--resume"), smoke_with(), used_directory),  # noqa: E501
    Case("run-out-is-a-file", "dem", RUN, ("is a file, not a directory",), smoke_with(), a_file_as_out),  # noqa: E501
    Case("run-resume-and-overwrite", "dem", (*RUN, "--resume", "--overwrite"), ("exclude each other",), smoke_with()),  # noqa: E501
    Case("run-resume-nothing", "dem", (*RUN, "--resume"), ("no run to continue", "without --resume"), smoke_with()),  # noqa: E501
    Case("run-resume-other-scene", "dem", ("run", "smoke", "--out", "{out}", "--resume"), ("is not the scene of run", "scene.toml"), setup=a_run_of_another_scene),  # noqa: E501
    Case("protocol-workers-zero", "dem", (*PROTOCOL, "--workers", "0"), ("--workers", "0 is out of range", ">= 1"), smoke_with()),  # noqa: E501
    Case("protocol-workers-text", "dem", (*PROTOCOL, "--workers", "two"), ("--workers", "not an integer"), smoke_with()),  # noqa: E501
    Case("protocol-pattern", "dem", (*PROTOCOL, "--pattern", "salty"), ("--pattern", "invalid choice", "acidic"), smoke_with()),  # noqa: E501
    Case("protocol-no-out", "dem", ("protocol", "smoke"), ("required", "--out")),
    Case("run-memory-beyond-machine", "dem", (*RUN, "--set", "particles.n_rods=10000000"), ("n_rods = 10000000", "GiB, this machine has", "lower n_rods"), smoke_with()),  # noqa: E501
    Case("protocol-memory-beyond-machine", "dem", (*PROTOCOL, "--set", "particles.n_rods=10000000"), ("GiB, this machine has", "--precision f32"), smoke_with()),  # noqa: E501
    Case("run-preset-unknown", "dem", (*RUN, "--preset", "quick"), ("--preset", "invalid choice", "balanced"), smoke_with()),  # noqa: E501
    Case("scene-preset-unknown", "dem", RUN, ("[scene] preset = 'quick'", "fast, balanced, accurate"), smoke_with(scene={"preset": "quick"})),  # noqa: E501
    Case("protocol-resume-nothing", "dem", (*PROTOCOL, "--resume"), ("holds no run to continue",), smoke_with()),  # noqa: E501
    Case("protocol-resume-and-overwrite", "dem", (*PROTOCOL, "--resume", "--overwrite"), ("exclude each other",), smoke_with()),  # noqa: E501
    Case("snapshot-no-file", "dem", ("snapshot", "{out}/none.npz", "--out", "{out}/x.vtu"), ("no such file", "checkpoint"), smoke_with()),  # noqa: E501
    Case("protocol-empty-scene", "dem", PROTOCOL, ("is empty",), ""),
    Case("protocol-used-directory", "dem", PROTOCOL, ("already holds", "--overwrite"), smoke_with(), used_directory),  # noqa: E501
    Case("protocol-out-is-a-file", "dem", PROTOCOL, ("is a file",), smoke_with(), a_file_as_out),
    Case("protocol-unknown-key", "dem", PROTOCOL, ("[protocol] unknown key(s) target_stress",), smoke_with(protocol={"target_stress": 3.0})),  # noqa: E501
    Case("protocol-target-negative", "dem", PROTOCOL, ("[protocol] target_mean_stress", "out of range"), smoke_with(protocol={"target_mean_stress": -1.0})),  # noqa: E501
    Case("protocol-path-states", "dem", PROTOCOL, ("save_path_states = true needs save_states",), smoke_with(protocol={"save_path_states": True, "save_states": False})),  # noqa: E501
    Case("protocol-probing-key", "dem", PROTOCOL, ("[probing] unknown key(s)",), smoke_with(probing={"amplitude": 1e-6})),  # noqa: E501
    Case("protocol-module-no-scene", "protocol", ("--out", "{out}"), ("required", "scene")),
    Case("run-set-unknown-key", "dem", (*RUN, "--set", "contact.muu=1"), ("[contact] unknown key(s) muu", "allowed keys"), smoke_with()),  # noqa: E501
    Case("run-set-no-section", "dem", (*RUN, "--set", "mu=0.2"), ("expected section.key=value",), smoke_with()),  # noqa: E501
    Case("protocol-set-out-of-range", "dem", (*PROTOCOL, "--set", "protocol.target_mean_stress=-3"), ("target_mean_stress = -3.0 is out of range",), smoke_with()),  # noqa: E501
    Case("protocol-set-bonds-rigid", "dem", (*PROTOCOL, "--set", "bonds.bending=1"), ("[bonds] is used only with",), smoke_with()),  # noqa: E501
    Case("protocol-set-rolling-no-cap", "dem", (*PROTOCOL, "--set", "contact.rolling_stiffness=1e4"), ("rolling_stiffness = 10000.0 needs rolling_friction > 0",), smoke_with()),  # noqa: E501
    Case("run-rolling-negative", "dem", RUN, ("[contact] rolling_friction", "out of range"), smoke_with(contact={"rolling_stiffness": 1e4, "rolling_friction": -0.5})),  # noqa: E501
    Case("protocol-module-empty-scene", "protocol", ("{scene}", "--out", "{out}"), ("is empty",), ""),  # noqa: E501
]

K0 = ("k0", "--sigma-v-max", "50", "--out", "{out}.nc")
TIV_CASES = [
    Case("tiv-k0-below-p0", "tiv", ("k0", "--sigma-v-max", "3", "--out", "x.nc"), ("--sigma-v-max 3 must be greater than --p0 5", "unload")),  # noqa: E501
    Case("tiv-isotropic-at-p0", "tiv", ("isotropic", "--p-max", "5", "--out", "x.nc"), ("--p-max 5 must be greater than --p0",)),  # noqa: E501
    Case("tiv-unload-below-p0", "tiv", ("unload", "--sigma-v-max", "4", "--out", "x.nc"), ("--sigma-v-max 4", "greater than --p0", "loads K0")),  # noqa: E501
    Case("tiv-radial-below-p0", "tiv", ("radial", "--eta", "0.3", "--p-max", "2", "--out", "x.nc"), ("--p-max 2", "greater than --p0")),  # noqa: E501
    Case("tiv-radial-eta-above-M", "tiv", ("radial", "--eta", "1.2", "--p-max", "100", "--out", "x.nc"), ("--eta 1.2", "|eta| < M = 1.1")),  # noqa: E501
    Case("tiv-radial-eta-at-minus-M", "tiv", ("radial", "--eta", "-1.1", "--p-max", "100", "--out", "x.nc"), ("|eta| < M",)),  # noqa: E501
    Case("tiv-radial-eta-own-M", "tiv", ("radial", "--eta", "0.6", "--p-max", "100", "--param", "M=0.5", "--out", "x.nc"), ("M = 0.5",)),  # noqa: E501
    Case("tiv-radial-eta-nan", "tiv", ("radial", "--eta", "nan", "--p-max", "100", "--out", "x.nc"), ("--eta nan", "not allowed")),  # noqa: E501
    Case("tiv-increments-zero", "tiv", (*K0, "--increments", "0"), ("--increments", "0 is out of range", "from 1 to 100,000")),  # noqa: E501
    Case("tiv-increments-huge", "tiv", (*K0, "--increments", "1000000000"), ("1,000,000,000 is out of range", "0.3 GB", "tiv_model.drivers")),  # noqa: E501
    Case("tiv-increments-text", "tiv", (*K0, "--increments", "ten"), ("--increments", "not an integer")),  # noqa: E501
    Case("tiv-unload-increments", "tiv", ("unload", "--sigma-v-max", "50", "--unload-increments", "-2", "--out", "x.nc"), ("--unload-increments", "out of range")),  # noqa: E501
    Case("tiv-p0-negative", "tiv", (*K0, "--p0", "-1"), ("--p0", "-1 is not allowed", "> 0")),
    Case("tiv-p0-nan", "tiv", (*K0, "--p0", "nan"), ("--p0", "nan is not allowed")),
    Case("tiv-p-max-inf", "tiv", ("isotropic", "--p-max", "inf", "--out", "x.nc"), ("--p-max", "inf is not allowed", "finite")),  # noqa: E501
    Case("tiv-p-max-text", "tiv", ("isotropic", "--p-max", "abc", "--out", "x.nc"), ("--p-max", "'abc' is not a number")),  # noqa: E501
    Case("tiv-param-unknown", "tiv", (*K0, "--param", "bogus=1"), ("unknown symbol 'bogus'", "lambda_star")),  # noqa: E501
    Case("tiv-param-range", "tiv", (*K0, "--param", "n=1.0"), ("(n, ", "= 1.0 is not allowed", "0 ≤ n < 1")),  # noqa: E501
    Case("tiv-param-no-equals", "tiv", (*K0, "--param", "z"), ("--param 'z'", "SYMBOL=VALUE")),
    Case("tiv-param-not-number", "tiv", (*K0, "--param", "n=abc"), ("'abc' is not a number",)),
    Case("tiv-anisotropy", "tiv", (*K0, "--anisotropy", "C"), ("--anisotropy", "invalid choice", "'A'")),  # noqa: E501
    Case("tiv-bound-law", "tiv", (*K0, "--bound-law", "linear"), ("--bound-law", "invalid choice")),  # noqa: E501
    Case("tiv-no-out", "tiv", ("k0", "--sigma-v-max", "50"), ("required", "--out")),
    Case("tiv-no-command", "tiv", (), ("required", "command")),
    Case("tiv-unknown-command", "tiv", ("triaxial",), ("invalid choice", "k0")),
    Case("tiv-out-is-a-folder", "tiv", ("k0", "--sigma-v-max", "50", "--out", "folder"), ("--out folder is a folder", "netCDF file"), setup=a_folder),  # noqa: E501
    Case("tiv-out-below-a-file", "tiv", ("k0", "--sigma-v-max", "50", "--out", "notes.txt/k0.nc"), ("is a file, not a folder",), setup=text_files),  # noqa: E501
    Case("tiv-probe-p-zero", "tiv", ("probe", "--p", "0"), ("--p", "0 is not allowed")),
    Case("tiv-unknown-option", "tiv", (*K0, "--steps", "3"), ("unrecognized arguments", "--steps")),  # noqa: E501
]

BRIDGE_CASES = [
    Case("bridge-no-history", "bridge", ("--out", "{out}"), ("--history is required", "--synthetic")),  # noqa: E501
    Case("bridge-history-missing", "bridge", ("--history", "none.nc", "--out", "{out}"), ("--history none.nc", "no such file")),  # noqa: E501
    Case("bridge-history-folder", "bridge", ("--history", "folder", "--out", "{out}"), ("is a folder",), setup=a_folder),  # noqa: E501
    Case("bridge-history-not-netcdf", "bridge", ("--history", "notes.txt", "--out", "{out}"), ("cannot read history file", "notes.txt"), setup=text_files),  # noqa: E501
    Case("bridge-history-wrong-variables", "bridge", ("--history", "wrong.nc", "--out", "{out}", "--stress-scale", "1"), ("no loading path could be read", "lacks variable(s)", "stress_xx"), setup=wrong_netcdf),  # noqa: E501
    Case("bridge-history-no-scale", "bridge", ("--history", "wrong.nc", "--out", "{out}"), ("no stress scale", "--stress-scale"), setup=wrong_netcdf),  # noqa: E501
    Case("bridge-probes-missing", "bridge", ("--history", "wrong.nc", "--probes", "p.nc", "--out", "{out}"), ("--probes p.nc", "no such file"), setup=wrong_netcdf),  # noqa: E501
    Case("bridge-stress-scale-zero", "bridge", ("--synthetic", "--out", "{out}", "--stress-scale", "0"), ("--stress-scale", "0 is not allowed", "> 0")),  # noqa: E501
    Case("bridge-stress-scale-negative", "bridge", ("--synthetic", "--out", "{out}", "--stress-scale", "-3"), ("--stress-scale", "not allowed")),  # noqa: E501
    Case("bridge-noise-negative", "bridge", ("--synthetic", "--out", "{out}", "--noise", "-1"), ("--noise", ">= 0")),  # noqa: E501
    Case("bridge-fabric-scale", "bridge", ("--synthetic", "--out", "{out}", "--fabric-scale", "0"), ("--fabric-scale", "not allowed")),  # noqa: E501
    Case("bridge-reference-pressure", "bridge", ("--synthetic", "--out", "{out}", "--reference-pressure", "nan"), ("--reference-pressure", "nan is not allowed")),  # noqa: E501
    Case("bridge-passes-zero", "bridge", ("--synthetic", "--out", "{out}", "--passes", "0"), ("--passes", "out of range")),  # noqa: E501
    Case("bridge-k0-increments", "bridge", ("--synthetic", "--out", "{out}", "--max-k0-increments", "0"), ("--max-k0-increments", "out of range")),  # noqa: E501
    Case("bridge-fix-unknown", "bridge", ("--synthetic", "--out", "{out}", "--fix", "bogus"), ("--fix bogus", "unknown symbol", "lambda_star")),  # noqa: E501
    Case("bridge-convention", "bridge", ("--synthetic", "--out", "{out}", "--convention", "cubic"), ("--convention", "invalid choice", "triaxial")),  # noqa: E501
    Case("bridge-probe-method", "bridge", ("--synthetic", "--out", "{out}", "--probe-method", "static"), ("--probe-method", "invalid choice")),  # noqa: E501
    Case("bridge-stages", "bridge", ("--synthetic", "--out", "{out}", "--stages", "nosuch"), ("--stages", "invalid choice")),  # noqa: E501
    Case("bridge-synthetic-and-history", "bridge", ("--synthetic", "--history", "h.nc", "--out", "{out}"), ("--synthetic makes its own inputs",)),  # noqa: E501
    Case("bridge-out-is-a-file", "bridge", ("--synthetic", "--out", "notes.txt"), ("--out notes.txt is a file",), setup=text_files),  # noqa: E501
    Case("bridge-stress-in-metres", "bridge", ("--history", "history.nc", "--probes", "probes.nc", "--out", "{out}"), ("history variable 'stress_yy' (stress) has units 'm'", "[length]", "allowed: a pressure unit"), setup=stress_in_metres),  # noqa: E501
    Case("bridge-modulus-in-kg", "bridge", ("--history", "history.nc", "--probes", "probes.nc", "--out", "{out}"), ("probes variable 'e_oed_v_linear' (modulus) has units 'kg'", "allowed: a pressure unit"), setup=modulus_in_kilograms),  # noqa: E501
    Case("bridge-stress-no-units", "bridge", ("--history", "history.nc", "--probes", "probes.nc", "--out", "{out}"), ("history variable 'stress_xx' (stress) has no units attribute", "allowed:"), setup=stress_without_units),  # noqa: E501
    Case("bridge-unknown-option", "bridge", ("--synthetic", "--out", "{out}", "--fast"), ("unrecognized arguments",)),  # noqa: E501
]

# issue 22: accepted, or blamed on the wrong thing, before; each now one line naming the key/file
NEWLINE = "contact.mu=0.2\ncontact.k_n=5"
SWEEP = ("sweep.toml", "--out", "{out}")
SMOKE_SWEEP = '[sweep]\nscene = "smoke"\n'
HISTORY = ("--history", "history.nc", "--probes", "probes.nc", "--out", "{out}")
ISSUE22_CASES = [
    Case("set-newline-drops-keys", "dem", (*RUN, "--set", NEWLINE), ("--set 'contact.mu=0.2\\ncontact.k_n=5'", "control character '\\n'", "one section.key=value per --set"), smoke_with()),  # noqa: E501
    Case("set-newline-in-string", "dem", (*RUN, "--set", 'scene.description="a\nb"'), ("--set", "control character '\\n'"), smoke_with()),  # noqa: E501
    Case("set-carriage-return", "dem", (*PROTOCOL, "--set", "contact.mu=0.2\r"), ("control character '\\r'",), smoke_with()),  # noqa: E501
    Case("protocol-module-set-newline", "protocol", ("{scene}", "--out", "{out}", "--set", NEWLINE), ("control character",), smoke_with()),  # noqa: E501
    Case("protocol-module-out-newline", "protocol", ("{scene}", "--out", "{out}\nx"), ("--out", "control character '\\n'"), smoke_with()),  # noqa: E501
    Case("scene-k_n-1e308", "dem", RUN, ("[contact] k_n = 1e+308 is out of range", "magnitudes 1e-12 to 1e+12"), smoke_with(contact={"k_n": 1e308})),  # noqa: E501
    Case("scene-k_n-tiny", "dem", RUN, ("[contact] k_n = 1e-300 is out of range",), smoke_with(contact={"k_n": 1e-300})),  # noqa: E501
    Case("set-k_n-1e308", "dem", (*RUN, "--set", "contact.k_n=1e308"), ("[contact] k_n = 1e+308",), smoke_with()),  # noqa: E501
    Case("scene-disc_mass-huge", "dem", RUN, ("[particles] disc_mass = 1e+308 is out of range",), smoke_with(particles={"disc_mass": 1e308})),  # noqa: E501
    Case("scene-disc_mass-tiny", "dem", RUN, ("[particles] disc_mass = 1e-300 is out of range",), smoke_with(particles={"disc_mass": 1e-300})),  # noqa: E501
    Case("scene-diameter-huge", "dem", RUN, ("[particles] diameter = 1e+300",), smoke_with(particles={"diameter": 1e300, "spacing": 1e300})),  # noqa: E501
    Case("scene-gamma_t-huge", "dem", RUN, ("[contact] gamma_t = 1e+308",), smoke_with(contact={"gamma_t": 1e308})),  # noqa: E501
    Case("scene-k_a_edge-huge", "dem", RUN, ("[long_range] k_a_edge = 1e+308",), smoke_with(long_range={"k_a_edge": 1e308})),  # noqa: E501
    Case("scene-strain-rate-huge", "dem", RUN, ("[control] compression_strain_rate = 1e+200",), smoke_with(control={"compression_strain_rate": 1e200})),  # noqa: E501
    Case("scene-relax_steps-huge", "dem", RUN, ("[control] relax_steps = 1000000000000000", "magnitudes"), smoke_with(control={"relax_steps": 10**15})),  # noqa: E501
    Case("protocol-target-huge", "dem", PROTOCOL, ("[protocol] target_mean_stress = 1e+300",), smoke_with(protocol={"target_mean_stress": 1e300})),  # noqa: E501
    Case("scene-dt_safety-tiny", "dem", RUN, ("[integration] dt_safety = 1e-300 is out of range", "[0.001, 0.5]"), smoke_with(integration={"dt_safety": 1e-300})),  # noqa: E501
    Case("scene-dt_safety-load-hang", "dem", RUN, ("[integration] dt_safety = 1e-06",), smoke_with(integration={"dt_safety": 1e-6})),  # noqa: E501
    Case("scene-k_t-ten-times-k_n", "dem", RUN, ("[contact] k_t = 1000000.0 is 10 × k_n = 100000.0", "k_t/k_n <= 6", "dt_safety = 0.15", "2/3 to 1"), smoke_with(contact={"k_t": 1e6})),  # noqa: E501
    Case("scene-k_t-equal-k_n-large-dt", "dem", RUN, ("k_t/k_n <= 0.844", "dt_safety = 0.4"), smoke_with(contact={"k_t": 1e5}, integration={"dt_safety": 0.4})),  # noqa: E501
    Case("set-k_n-below-k_t", "dem", (*PROTOCOL, "--set", "contact.k_n=1000"), ("[contact] k_t = 20000.0 is 20 × k_n = 1000.0",), smoke_with()),  # noqa: E501
    Case("scene-not-utf8", "dem", ("run", "scene.toml", "--out", "{out}"), ("scene file 'scene.toml' is not UTF-8", "byte 0xe8", "save it as UTF-8"), setup=not_utf8_scene),  # noqa: E501
    Case("scene-binary", "dem", ("run", "scene.toml", "--out", "{out}"), ("scene file 'scene.toml' is not UTF-8", "offset 0"), setup=binary_scene),  # noqa: E501
    Case("protocol-scene-not-utf8", "protocol", ("scene.toml", "--out", "{out}"), ("scene file 'scene.toml' is not UTF-8",), setup=not_utf8_scene),  # noqa: E501
    Case("sweep-file-not-utf8", "sweep", SWEEP, ("sweep file 'sweep.toml' is not UTF-8",), setup=sweep_bytes(SMOKE_SWEEP.encode() + b"# \xe9t\xe9\n")),  # noqa: E501
    Case("sweep-scene-not-utf8", "sweep", SWEEP, ("[sweep] scene file", "base.toml' is not UTF-8"), setup=sweep_file('[sweep]\nscene = "base.toml"\n[sweep.grid]\n"scene.seed" = [1]\n', b"[particles]\n# \xff\n")),  # noqa: E501
    Case("sweep-member-dotdot", "sweep", SWEEP, ("[[sweep.members]] #1 name = '..'", "not '.' or '..'"), setup=sweep_file(SMOKE_SWEEP + '[[sweep.members]]\nname = ".."\n')),  # noqa: E501
    Case("sweep-member-slash", "sweep", SWEEP, ("name = 'a/b'", "no path separator"), setup=sweep_file(SMOKE_SWEEP + '[[sweep.members]]\nname = "a/b"\n')),  # noqa: E501
    Case("sweep-set-k_n-1e308", "sweep", SWEEP, ("member base (no keys): [contact] k_n = 1e+308",), setup=sweep_file(SMOKE_SWEEP + '[sweep.set]\n"contact.k_n" = 1e308\n[[sweep.members]]\nname = "base"\n')),  # noqa: E501
    Case("sweep-grid-k_t-ten-times", "sweep", SWEEP, ("member k_t-1e06", "[contact] k_t = 1000000.0 is 10 × k_n"), setup=sweep_file(SMOKE_SWEEP + '[sweep.grid]\n"contact.k_t" = [1e6]\n')),  # noqa: E501
    Case("sweep-out-newline", "sweep", ("sweep.toml", "--out", "o\nut"), ("--out", "control character '\\n'"), setup=sweep_file(SMOKE_SWEEP + '[sweep.grid]\n"scene.seed" = [1]\n')),  # noqa: E501
    Case("run-out-newline", "dem", ("run", "{scene}", "--out", "o\nut"), ("--out 'o\\nut'", "control character '\\n'", "on one line"), smoke_with()),  # noqa: E501
    Case("run-out-equals-carriage-return", "dem", ("run", "{scene}", "--out=out\r"), ("--out 'out\\r'", "control character '\\r'"), smoke_with()),  # noqa: E501
    Case("run-out-tab", "dem", ("run", "{scene}", "--out", "o\tut"), ("--out", "control character '\\t'"), smoke_with()),  # noqa: E501
    Case("run-scene-newline", "dem", ("run", "scene.toml\n", "--out", "{out}"), ("argument 'scene.toml\\n'", "control character"), smoke_with()),  # noqa: E501
    Case("protocol-out-newline", "dem", ("protocol", "{scene}", "--out", "o\nut"), ("protocol: error: --out 'o\\nut'", "control character '\\n'"), smoke_with()),  # noqa: E501
    Case("protocol-out-escape", "dem", ("protocol", "{scene}", "--out", "o\x1b[2Jut"), ("--out", "control character '\\x1b'"), smoke_with()),  # noqa: E501
    Case("snapshot-out-newline", "dem", ("snapshot", "state.npz", "--out", "s\n.vtu"), ("--out 's\\n.vtu'", "control character")),  # noqa: E501
    Case("snapshot-stage-newline", "dem", ("snapshot", "state.npz", "--out", "s.vtu", "--stage", "A\nB"), ("--stage 'A\\nB'",)),  # noqa: E501
    Case("anisotropy-dir-newline", "anisotropy", ("ru\nn",), ("argument 'ru\\nn'", "control character")),  # noqa: E501
    Case("sweep-summarise-out-newline", "sweep", ("summarise", ".", "--out", "a\n.md"), ("--out", "control character '\\n'")),  # noqa: E501
    Case("tiv-param-k-1e308", "tiv", (*K0, "--param", "k=1e308"), ("parameter bulk_stiffness_coefficient (k", "|k| <= 1e+08")),  # noqa: E501
    Case("tiv-param-r-1e300", "tiv", (*K0, "--param", "r=1e300"), ("(r, preconsolidation exponent", "|r| <= 1e+08")),  # noqa: E501
    Case("tiv-param-N-1e308", "tiv", (*K0, "--param", "N=1e308"), ("ncl_intercept (N", "|N| <= 1e+08")),  # noqa: E501
    Case("tiv-param-lambda-tiny", "tiv", (*K0, "--param", "lambda_star=1e-300"), ("parameters r, n, lambda_star", "energy exponent")),  # noqa: E501
    Case("tiv-param-g-times-p_r", "tiv", (*K0, "--param", "g=1e7", "--param", "p_r=1e3"), ("parameters g, p_r", "shear modulus scale g p_r = 1e+10")),  # noqa: E501
    Case("tiv-param-newline", "tiv", (*K0, "--param", "n=0.2\nM=3"), ("--param 'n=0.2\\nM=3'", "is not a number")),  # noqa: E501
    Case("bridge-history-2d-stress", "bridge", HISTORY, ("history variable 'stress_xx' has dimensions ('time', 'x')", "one value per record"), setup=stress_2d),  # noqa: E501
    Case("bridge-history-scalar-stress", "bridge", HISTORY, ("history variable 'stress_yy' has dimensions ()",), setup=stress_scalar),  # noqa: E501
    Case("bridge-history-no-records", "bridge", HISTORY, ("history has no records", "'time' is empty"), setup=history_empty),  # noqa: E501
    Case("bridge-history-text-volume", "bridge", HISTORY, ("history variable 'specific_volume' has type", "needs numbers"), setup=stress_as_text),  # noqa: E501
    Case("bridge-history-two-dimensions", "bridge", HISTORY, ("'specific_volume' is along ('record',)", "share one record dimension"), setup=volume_on_another_dimension),  # noqa: E501
    Case("bridge-probes-flat-tensor", "bridge", HISTORY, ("probes dataset variable 'stiffness_tensor_linear'", "i, j >= 2"), setup=tensor_flat),  # noqa: E501
    Case("bridge-probes-2d-modulus", "bridge", HISTORY, ("probes dataset variable 'e_oed_v_linear' has dimensions ('probe', 'y')",), setup=probe_moduli_2d),  # noqa: E501
]

# fmt: on
CASES = DEM_CASES + TIV_CASES + BRIDGE_CASES + ISSUE22_CASES


def entry(name: str):
    if name == "dem":
        from dem_taichi.cli.commands import main
    elif name == "protocol":
        from dem_taichi.protocol.runner import main
    elif name == "tiv":
        from tiv_model.cli import main
    elif name == "sweep":
        from dem_taichi.sweep.command import main
    elif name == "anisotropy":
        from dem_taichi.response.anisotropy import main
    else:
        from bridge.pipeline import main
    return main


def test_there_are_at_least_eighty_cases():
    assert len(CASES) >= 80
    assert len({case.id for case in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[case.id for case in CASES])
def test_bad_input_is_one_clear_line(case, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    if case.scene is not None:
        (tmp_path / "scene.toml").write_text(case.scene)
    if case.setup is not None:
        case.setup(tmp_path)
    argv = [a.replace("{scene}", "scene.toml").replace("{out}", "out") for a in case.argv]
    code = entry(case.entry)(argv)
    out, err = capsys.readouterr()
    assert code == case.code, err
    assert "Traceback" not in out + err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert ": error: " in lines[0]
    for words in case.words:
        assert words in lines[0], (words, lines[0])


def test_debug_shows_the_error_itself(tmp_path, monkeypatch):
    from dem_taichi.cli.commands import main
    from dem_taichi.scene.config import SceneError

    monkeypatch.chdir(tmp_path)
    (tmp_path / "scene.toml").write_text("")
    with pytest.raises(SceneError, match="is empty"):
        main(["run", "scene.toml", "--out", "out", "--debug"])


@pytest.mark.parametrize(
    "command, words",
    [
        (["dem_taichi", "run", "scene.toml", "--out", "o"], "is empty"),
        (["dem_taichi", "protocol", "scene.toml", "--out", "o", "--quiet"], "is empty"),
        (["dem_taichi.protocol", "scene.toml", "--out", "o"], "is empty"),
        (["tiv_model", "k0", "--sigma-v-max", "1", "--out", "k0.nc"], "greater than --p0"),
        (["bridge.pipeline", "--history", "none.nc", "--out", "b"], "no such file"),
    ],
)
def test_the_real_command_lines(command, words, tmp_path):
    (tmp_path / "scene.toml").write_text("")
    env_python = [sys.executable, "-m", *command]
    result = subprocess.run(env_python, cwd=tmp_path, capture_output=True, text=True)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and words in result.stderr
    debug = subprocess.run([*env_python, "--debug"], cwd=tmp_path, capture_output=True, text=True)
    assert debug.returncode != 0 and "Traceback" in debug.stderr


# -- the Python APIs: each bad call raises at once, with a message naming what is wrong -------
@functools.cache
def _simulation():
    """One smoke-scene Simulation for the argument checks of ``run`` (Taichi starts once)."""
    from dem_taichi import Simulation

    return Simulation(load_scene("smoke"))


def _api_cases():
    from bridge.pipeline import calibrate_from_results, calibrate_on_replicas
    from bridge.series import SeriesError
    from dem_taichi import Simulation, load_scene, run_protocol
    from dem_taichi.io.run_directory import RunDirectoryError
    from dem_taichi.protocol.cost import estimate_cost
    from dem_taichi.scene.config import SceneError, scene_with_overrides
    from dem_taichi.scene.options import with_preset
    from dem_taichi.sweep.results import open_sweep
    from dem_taichi.sweep.spec import SweepError, sweep_from_toml
    from tiv_model import TABLE1, ModelOptions, drivers
    from tiv_model.errors import ParameterError

    def smoke():
        return load_scene("smoke")

    def sim():
        return _simulation()

    def latin1(t, name):
        path = t / name
        path.write_bytes("[sweep]\nscene = 'smoke' # très\n".encode("latin-1"))
        return path

    def flat_history():
        from bridge.series import Convention
        from bridge.synthetic import synthetic_results

        history = synthetic_results(TABLE1, convention=Convention(50.0), increments=2,
                                    unloading_increments=1).history  # fmt: skip
        history["fabric_deviator"] = (("time", "x"), np.zeros((history.sizes["time"], 2)))
        return history, Convention(50.0)

    from bridge.series import path_series
    from dem_taichi.sweep.spec import load_sweep

    grid = (
        '[sweep]\nscene = "smoke"\n[sweep.grid]\n'
        f'"scene.seed" = [{", ".join(map(str, range(1, 101)))}]\n'
        f'"output.every" = [{", ".join(map(str, range(1, 102)))}]\n'
    )

    # fmt: off
    return [
        ("Simulation.run-nan", lambda t: sim().run(float("nan")), ValueError, "n_steps = nan: must be a whole number"),  # noqa: E501
        ("Simulation.run-inf", lambda t: sim().run(math.inf), ValueError, "n_steps = inf"),
        ("Simulation.run-negative", lambda t: sim().run(-3), ValueError, "n_steps = -3 is out of range: allowed integers >= 0"),  # noqa: E501
        ("Simulation.run-fraction", lambda t: sim().run(2.5), ValueError, "n_steps = 2.5"),
        ("Simulation.run-bool", lambda t: sim().run(True), ValueError, "n_steps = True: must be an integer"),  # noqa: E501
        ("Simulation.run-text", lambda t: sim().run("100"), ValueError, "n_steps = '100'"),
        ("Simulation.run-output_every-zero", lambda t: sim().run(10, output_every=0), ValueError, "output_every = 0 is out of range"),  # noqa: E501
        ("Simulation.run-output_every-negative", lambda t: sim().run(10, output_every=-5), ValueError, "output_every = -5"),  # noqa: E501
        ("scene_with_overrides-newline", lambda t: scene_with_overrides(smoke(), ["contact.mu=0.2\ncontact.k_n=5"]), SceneError, "control character '\\n'"),  # noqa: E501
        ("Scene.replace-k_n-huge", lambda t: smoke().replace(contact={"k_n": 1e300}), SceneError, "[contact] k_n = 1e+300 is out of range"),  # noqa: E501
        ("load_scene-not-utf8", lambda t: load_scene(latin1(t, "s.toml")), SceneError, "s.toml' is not UTF-8 text (byte 0xe8 at offset 28)"),  # noqa: E501
        ("load_sweep-not-utf8", lambda t: load_sweep(latin1(t, "w.toml")), SweepError, "sweep file"),  # noqa: E501
        ("sweep_from_toml-grid-too-large", lambda t: sweep_from_toml(grid), SweepError, "makes 10,100 members (100 × 101): allowed at most 10,000"),  # noqa: E501
        ("Parameters-k-1e308", lambda t: TABLE1.replace(k=1e308), ParameterError, "need |k| <= 1e+08"),  # noqa: E501
        ("Parameters-lambda-tiny", lambda t: TABLE1.replace(lambda_star=1e-300), ParameterError, "energy exponent"),  # noqa: E501
        ("path_series-2d-fabric", lambda t: path_series(*flat_history()[:1], "k0", flat_history()[1]), SeriesError, "'fabric_deviator' has dimensions ('time', 'x')"),  # noqa: E501
        ("Simulation-unknown-scene", lambda t: Simulation("nope"), SceneError, "no built-in scene 'nope'"),  # noqa: E501
        ("Simulation-not-a-scene", lambda t: Simulation(42), SceneError, "scene = 42: give a built-in scene name"),  # noqa: E501
        ("Simulation-arch", lambda t: Simulation(smoke(), arch="tpu"), ValueError, "cpu | gpu"),
        ("Simulation-precision", lambda t: Simulation(smoke(), precision="f16"), ValueError, "f64 | f32"),  # noqa: E501
        ("Simulation-execution", lambda t: Simulation(smoke(), execution="fast"), ValueError, "auto|serial|parallel|gather"),  # noqa: E501
        ("load_scene-empty", lambda t: load_scene(""), SceneError, "scene = '': give"),
        ("run_protocol-workers", lambda t: run_protocol("smoke", t / "a", workers=0), ValueError, "workers = 0"),  # noqa: E501
        ("run_protocol-pattern", lambda t: run_protocol("smoke", t / "b", pattern="sour"), ValueError, "acidic | basic | neutral"),  # noqa: E501
        ("run_protocol-resume-nothing", lambda t: run_protocol("smoke", t / "c", resume=True), RunDirectoryError, "no run to continue"),  # noqa: E501
        ("scene_with_overrides-no-value", lambda t: scene_with_overrides(smoke(), ["contact.mu"]), SceneError, "expected section.key=value"),  # noqa: E501
        ("scene_with_overrides-unknown", lambda t: scene_with_overrides(smoke(), ["contact.mux=1"]), SceneError, "unknown key(s) mux"),  # noqa: E501
        ("Scene.replace-k_t-beyond-the-bound", lambda t: smoke().replace(contact={"k_t": 1e6}), SceneError, "[contact] k_t = 1000000.0 is 10 × k_n = 100000.0: allowed k_t/k_n <= 6"),  # noqa: E501
        ("Scene.replace-k_n-below-k_t", lambda t: smoke().replace(contact={"k_n": 300.0}), SceneError, "[contact] k_t = 20000.0 is 66.7 × k_n = 300.0"),  # noqa: E501
        ("Scene.replace-acidic-two-discs", lambda t: smoke().replace(particles={"n_spheres": 2}, long_range={"enabled": True, "pattern": "acidic"}), SceneError, "pattern = 'acidic' needs n_spheres >= 3"),  # noqa: E501
        ("Scene.replace-unknown-key", lambda t: smoke().replace(particles={"n_rodz": 3}), SceneError, "unknown key(s) n_rodz"),  # noqa: E501
        ("Scene.replace-unknown-section", lambda t: smoke().replace(partikles={}), SceneError, "no such section"),  # noqa: E501
        ("with_preset-unknown", lambda t: with_preset(smoke(), "quick"), SceneError, "fast, balanced, accurate"),  # noqa: E501
        ("estimate_cost-command", lambda t: estimate_cost(smoke(), "walk"), ValueError, "run | protocol"),  # noqa: E501
        ("sweep_from_toml-scene", lambda t: sweep_from_toml("[sweep]\nscene = 5\n"), SweepError, "[sweep] scene = 5"),  # noqa: E501
        ("open_sweep-not-a-sweep", lambda t: open_sweep(t), FileNotFoundError, "not a sweep directory"),  # noqa: E501
        ("Parameters-negative", lambda t: TABLE1.replace(lambda_star=-1.0), ParameterError, "need 0 < lambda_star"),  # noqa: E501
        ("drivers.k0-negative", lambda t: drivers.k0(sigma_v_max=-5.0), ParameterError, "sigma_v_max = -5.0"),  # noqa: E501
        ("drivers.k0-increments", lambda t: drivers.k0(increments=0), ParameterError, "increments = 0"),  # noqa: E501
        ("ModelOptions-anisotropy", lambda t: ModelOptions(anisotropy="C"), ParameterError, "use 'A' or 'B'"),  # noqa: E501
        ("calibrate_from_results-missing", lambda t: calibrate_from_results(t / "h.nc", None, t / "o"), FileNotFoundError, "does not exist"),  # noqa: E501
        ("calibrate_from_results-option", lambda t: calibrate_from_results(t / "h.nc", None, t / "o", {"nonsense": 1}), TypeError, "unknown pipeline option(s) ['nonsense']"),  # noqa: E501
        ("calibrate_on_replicas-not-runs", lambda t: calibrate_on_replicas([t], t / "r"), SeriesError, "neither a protocol run"),  # noqa: E501
    ]
    # fmt: on


API_CASES = _api_cases()


@pytest.mark.parametrize(
    ("call", "error", "words"), [c[1:] for c in API_CASES], ids=[c[0] for c in API_CASES]
)
def test_python_api_bad_input_raises_with_a_clear_message(call, error, words, tmp_path):
    with pytest.raises(error) as raised:
        call(tmp_path)
    assert words in str(raised.value)
    assert "\n" not in str(raised.value).strip()  # one line


def test_all_entry_points_together_exceed_eighty_cases():
    assert len(CASES) + len(API_CASES) >= 140
