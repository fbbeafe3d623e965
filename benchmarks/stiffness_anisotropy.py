"""Frozen-network experiment matrix on the stiffness anisotropy (issue 8,
docs/science/dem-model.md §1.7).

For every stored relaxed state of a protocol run (``state_*.npz`` and, with
``[protocol] save_path_states = true``, every ``path_*.npz`` increment), the zero-amplitude
constrained moduli E_oed,v = C_yyyy and E_oed,h = C_xxxx of the *same* network and forces under
changed stiffness assumptions:

- ``rigid``: today's rigid rods and springs (stuck contacts, the protocol probes' default);
- ``chain_kb<x>``: bonded rods, bonds k_bn = k_n, k_bt = k_t of the scene, κ_b = x k_n d²
  (MercuryDPM's bonds share the contact springs);
- ``bend_kb<x>``: only bending is soft (k_bn = k_bt = 1e6 k_n): isolates bending;
- ``rigid_kt<y>_<stuck|free>``: rigid rods, stuck k_t = y k_n, contacts at the Coulomb cap
  stuck or sliding freely;
- ``rigid_roll``: rigid rods with rolling springs κ_r = k_n d²/4 at contacts (k_r = k_n);
- ``mercury_kr<z>``: MercuryDPM-like chains, k_r = z k_n for the bonds' bending
  (κ_b = k_r (d/2)²) and for rolling springs at inter-rod contacts;
- ``rigid_lr1000``: long-range stiffness × 1000;
- ``chain_kb0.1_nopre``: chain κ_b = 0.1 without the bonds' pre-forces (their effect);
- ``chainkt1_kb<x>``: chains with k_t = k_n at contacts and k_bt = k_n in the bonds (bending and
  stiff tangential springs together).

Every response is checked for stability: the inertia of the symmetric part of its reduced
Hessian (``SolverInfo.n_negative_modes``). A frozen network with negative modes is not stable
under its own forces (pre-stressed soft rods buckle; frictionless rigid rods are hypostatic) and
its moduli are reported as "unstable", never used.

The dynamic probes start, as the protocol's, from the state relaxed further to the probes' UFR
([probing] relax_unbalanced_force); the frozen-network responses use the stored state as it is
(the rigid one equals the protocol's own probe, made after that relaxation, within 0.1 % on the
paper run).

Per state it also gives the contact branch-vector ratio Σ l_x²/Σ l_y² and the affine
normal-spring ratio (the rigid upper bounds, :mod:`dem_taichi.response.anisotropy`). With
``--dynamic-states`` it runs one-sided and ± dynamic strain probes at those states
(``--amplitudes``), next to the linear responses (free and stuck).

Writes ``<out>/stiffness_anisotropy_matrix.csv``, ``.md`` (tables; the isotropic-path states
A, A→B, B are the control) and ``.png`` (E_h/E_v against κ_b at each state).

    python benchmarks/stiffness_anisotropy.py RUN_DIR [--out benchmarks/results]
           [--relax-ufr 1e-7] [--dynamic-states "C,B'"] [--amplitudes 1e-7,1e-6,1e-5,1e-4]
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dem_taichi.physics import forcelaw
from dem_taichi.response.anisotropy import network_anisotropy
from dem_taichi.response.flexible import BondStiffness, flexible_response
from dem_taichi.response.linear import StiffnessVariant, linear_response

KAPPAS = (1.0, 0.3, 0.1, 0.03, 0.01)
ISOTROPIC_PATHS = ("A", "A_to_B", "B")


@dataclass(frozen=True)
class Variant:
    """One stiffness assumption: bonds (None = rigid rods), contact variant, sliding mode."""

    name: str
    family: str
    bonds: BondStiffness | None
    stiffness: StiffnessVariant
    sliding: str = "stuck"
    kappa: float = math.inf  # κ_b / (k_n d²), inf for rigid rods


def variants(k_n: float, k_t: float, d: float) -> list[Variant]:
    """The experiment matrix (see the module docstring)."""
    base = StiffnessVariant()
    out = [Variant("rigid", "rigid", None, base)]
    for x in KAPPAS:
        chain = BondStiffness(k_n, k_t, x * k_n * d**2)
        out.append(Variant(f"chain_kb{x:g}", "chain", chain, base, kappa=x))
    for x in KAPPAS:
        bend = BondStiffness(1e6 * k_n, 1e6 * k_n, x * k_n * d**2)
        out.append(Variant(f"bend_kb{x:g}", "bend", bend, base, kappa=x))
    for y in (0.0, 0.2, 0.5, 1.0):
        for mode in ("stuck", "free"):
            out.append(
                Variant(
                    f"rigid_kt{y:g}_{mode}",
                    "kt",
                    None,
                    StiffnessVariant(tangential_stiffness=y * k_n),
                    mode,
                )
            )
    out.append(
        Variant(
            "rigid_roll", "rolling", None, StiffnessVariant(rolling_stiffness=0.25 * k_n * d**2)
        )
    )
    for z in (1.0, 0.1, 0.01):
        kappa = z * k_n * (0.5 * d) ** 2
        out.append(
            Variant(
                f"mercury_kr{z:g}",
                "mercury",
                BondStiffness(k_n, k_t, kappa),
                StiffnessVariant(rolling_stiffness=kappa),
                kappa=kappa / (k_n * d**2),
            )
        )
    out.append(Variant("rigid_lr1000", "long_range", None, StiffnessVariant(long_range_factor=1e3)))
    nopre = BondStiffness(k_n, k_t, 0.1 * k_n * d**2, pre_force="none")
    out.append(Variant("chain_kb0.1_nopre", "chain_nopre", nopre, base, kappa=0.1))
    for x in (1.0, 0.3, 0.1):
        bonds = BondStiffness(k_n, k_n, x * k_n * d**2)
        out.append(
            Variant(
                f"chainkt1_kb{x:g}",
                "chain_kt1",
                bonds,
                StiffnessVariant(tangential_stiffness=k_n),
                kappa=x,
            )
        )
    return out


def state_files(run_dir: Path) -> list[tuple[str, str, int, Path]]:
    """(label, path, increment, file) of the stored states, in loading order."""
    found = []
    for f in run_dir.glob("state_*.npz"):
        label = f.stem[6:].replace("_prime", "'")
        path = {"A": "A", "B": "B", "C": "A_to_C", "B'": "C_to_B"}.get(label, label)
        found.append((label, path, 10_000, f))
    for f in run_dir.glob("path_*.npz"):
        m = re.fullmatch(r"path_(.+)_(\d{3})", f.stem)
        if m:
            found.append((f"{m.group(1)}_{int(m.group(2))}", m.group(1), int(m.group(2)), f))
    order = {"A": 0, "A_to_B": 1, "B": 2, "A_to_C": 3, "C_to_B": 4}
    return sorted(found, key=lambda s: (order.get(s[1], 5), s[1], s[2]))


def relaxed_sim(file: Path, ufr: float | None):
    """The stored state in an engine, optionally relaxed further at fixed cell to ``ufr``."""
    from dem_taichi.engine.simulation import Simulation
    from dem_taichi.protocol.runner import relax
    from dem_taichi.scene.protocol_sections import protocol_settings

    sim = Simulation.from_checkpoint(file)
    info = {"relax_steps": 0, "relaxed": True}
    if ufr is not None:
        config = protocol_settings(sim.scene)
        start = sim.step
        _, ok, _ = relax(sim, "probe", ufr, math.inf, config.relax_check_steps, 200_000)
        info = {"relax_steps": sim.step - start, "relaxed": bool(ok)}
    return sim, info


def _is_stable(r) -> bool:
    """Stuck contacts: no negative mode of the symmetric part of H (stuck springs make H nearly
    symmetric, so its inertia is a stability test). Free sliding makes H non-symmetric (the
    Coulomb slope), and then the inertia of its symmetric part proves nothing: positive moduli
    and a regular solve are all that is checked."""
    if r.solver.regularised:
        return False
    if r.sliding_contacts == "stuck":
        return r.solver.n_negative_modes == 0
    return r.e_oed_v > 0.0 and r.e_oed_h > 0.0 and r.bulk_modulus > 0.0


def matrix_rows(label, path, increment, snap, measures, variant_list) -> list[dict]:
    """E_oed,v, E_oed,h of every variant on one snapshot."""
    aniso = network_anisotropy(snap)
    pairs = forcelaw.pair_forces(snap)
    lx2, ly2 = np.sum(pairs.branch[pairs.in_contact] ** 2, axis=0)
    rows, reference = [], None
    for v in variant_list:
        t0 = time.perf_counter()
        if v.bonds is None:
            r = linear_response(snap, v.sliding, variant=v.stiffness, stability=True)
        else:
            r = flexible_response(snap, v.bonds, v.sliding, variant=v.stiffness, stability=True)
        seconds = time.perf_counter() - t0
        if reference is None:
            reference = r
        rows.append(
            dict(
                state=label,
                path=path,
                increment=increment,
                p=measures["mean_stress"],
                q=measures["deviatoric_stress"],
                v=measures["specific_volume"],
                fabric=measures["fabric_deviator"],
                variant=v.name,
                family=v.family,
                kappa_b=v.kappa,
                bond_normal=v.bonds.normal if v.bonds else math.inf,
                bond_shear=v.bonds.shear if v.bonds else math.inf,
                k_t=v.stiffness.k_t(snap),
                sliding=v.sliding,
                rolling=v.stiffness.rolling_stiffness,
                long_range_factor=v.stiffness.long_range_factor,
                e_v=r.e_oed_v,
                e_h=r.e_oed_h,
                ratio=r.e_oed_h / r.e_oed_v,
                e_v_over_rigid=r.e_oed_v / reference.e_oed_v,
                bulk=r.bulk_modulus,
                shear=r.voigt_shear_modulus,
                residual=r.solver.residual,
                unbalanced=r.solver.unbalanced_force,
                regularised=r.solver.regularised,
                n_negative=r.solver.n_negative_modes,
                stable=_is_stable(r),
                seconds=seconds,
                branch_ratio=lx2 / ly2,
                affine_ratio=aniso.affine_ratio_contact,
                contact_normal_deviator=aniso.contact_normal_deviator,
            )
        )
    return rows


def dynamic_rows(label, sim, amplitudes) -> list[dict]:
    """One-sided and ± dynamic probes at the current (relaxed) state, beside the linear ones."""
    from dem_taichi.protocol.probing import dynamic_modulus
    from dem_taichi.protocol.runner import relax
    from dem_taichi.scene.probing_sections import probing_settings
    from dem_taichi.scene.protocol_sections import protocol_settings

    probing, protocol = probing_settings(sim.scene), protocol_settings(sim.scene)
    # as the protocol's probes: relax the copy further to the probes' UFR first (a path state
    # relaxed to the path's UFR still creeps, differently under + and − probes)
    relax(
        sim,
        "probe",
        probing.relax_unbalanced_force,
        math.inf,
        protocol.relax_check_steps,
        probing.relax_max_steps,
    )
    base = sim.get_state()
    sigma0 = sim.measure()
    snap = sim.snapshot()
    linear = {m: linear_response(snap, m) for m in ("stuck", "free")}
    rows = []
    for axis, key, name in (("y", "stress_yy", "e_oed_v"), ("x", "stress_xx", "e_oed_h")):
        for a in amplitudes:
            t0 = time.perf_counter()
            e, d = dynamic_modulus(sim, axis, a, probing, protocol, base)
            plus = (d["stress"][0] - sigma0[key]) / d["strain"][0]
            minus = (d["stress"][1] - sigma0[key]) / d["strain"][1]
            rows.append(
                dict(
                    state=label,
                    modulus=name,
                    amplitude=a,
                    two_sided=e,
                    plus=plus,
                    minus=minus,
                    linear_stuck=getattr(linear["stuck"], name),
                    linear_free=getattr(linear["free"], name),
                    relaxed=all(d["relaxed"]),
                    seconds=time.perf_counter() - t0,
                )
            )
    sim.set_state(base)
    return rows


def _fmt(x, digits=3):
    return "nan" if not np.isfinite(x) else f"{x:.{digits}g}"


def _header(head: list[str]) -> list[str]:
    """The two header lines of a markdown table."""
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]


def _cell(row: dict, key: str) -> str:
    """A modulus cell, or "unst." where the frozen network has negative modes."""
    return _fmt(row[key]) if _stable(row) else f"unst. ({row['n_negative']})"


def _stable(row: dict) -> bool:
    value = row["stable"]
    return value if isinstance(value, bool) else value == "True"


def markdown(rows: list[dict], dyn: list[dict], run_dir: Path) -> str:
    """Tables: E_h/E_v by state and variant; E_v/E_v,rigid; isotropic-path control; dynamic."""
    names = list(dict.fromkeys(r["variant"] for r in rows))
    states = list(dict.fromkeys(r["state"] for r in rows))
    by = {(r["state"], r["variant"]): r for r in rows}
    out = [f"# Stiffness-anisotropy matrix on `{run_dir}`", ""]
    out += [
        "E_h/E_v (linear response, frozen network at the stored forces); rows: states in",
        "loading order (A, A→B, B: the isotropic control; A→C ending at C; C→B ending at B′).",
        "",
    ]
    head = ["state", "p", "fabric", "Σlx²/Σly²", "affine"] + names
    out += _header(head)
    for s in states:
        r0 = by[(s, names[0])]
        cells = [
            s,
            _fmt(r0["p"]),
            f"{r0['fabric']:+.3f}",
            _fmt(r0["branch_ratio"]),
            _fmt(r0["affine_ratio"]),
        ] + [_cell(by[(s, n)], "ratio") for n in names]
        out.append("| " + " | ".join(cells) + " |")
    out += ["", "E_v / E_v(rigid) (how much softer vertically than today's rigid rods)", ""]
    head = ["state"] + names
    out += _header(head)
    for s in states:
        out.append(
            "| " + " | ".join([s] + [_cell(by[(s, n)], "e_v_over_rigid") for n in names]) + " |"
        )
    out += ["", "Isotropic control (A, A→B, B) and K0/unloading summary per variant", ""]
    head = [
        "variant",
        "E_h/E_v iso mean ± sd (n)",
        "E_h/E_v at C",
        "at B′",
        "B′ − B",
        "E_v/p at B",
        "p-exponent of E_v (iso)",
        "unstable states",
    ]
    out += _header(head)
    summary = variant_summary(rows)
    for n in names:
        s = summary[n]
        out.append(
            f"| {n} | {s['iso_mean']:.3f} ± {s['iso_sd']:.3f} ({s['iso_n']}) | "
            f"{_fmt(s['ratio_C'])} | {_fmt(s['ratio_Bp'])} | {s['ratio_Bp'] - s['ratio_B']:+.3f} | "
            f"{_fmt(s['ev_over_p_B'])} | {_fmt(s['exponent'])} | {s['unstable']} |"
        )
    if dyn:
        out += ["", "Dynamic probes (one-sided +/−, two-sided) against the linear response", ""]
        head = [
            "state",
            "modulus",
            "amplitude",
            "+",
            "−",
            "±",
            "linear stuck",
            "linear free",
            "relaxed",
            "s",
        ]
        out += _header(head)
        for d in dyn:
            out.append(
                f"| {d['state']} | {d['modulus']} | {d['amplitude']:.0e} | {_fmt(d['plus'], 5)} | "
                f"{_fmt(d['minus'], 5)} | {_fmt(d['two_sided'], 5)} | "
                f"{_fmt(d['linear_stuck'], 5)} | {_fmt(d['linear_free'], 5)} | "
                f"{d['relaxed']} | {d['seconds']:.0f} |"
            )
    return "\n".join(out) + "\n"


def variant_summary(rows: list[dict]) -> dict[str, dict]:
    """Per variant: isotropic-path E_h/E_v mean ± sd, E_h/E_v at C, B, B′, E_v/p at B, and the
    p-exponent of E_v along the isotropic path (least squares of ln E_v on ln p, over the states
    where both are positive: a stable network can still give E_v ≤ 0 under a variant that frees
    a mechanism, e.g. sliding contacts on a small sample)."""
    out = {}
    for n in dict.fromkeys(r["variant"] for r in rows):
        every = [r for r in rows if r["variant"] == n]
        mine = [r for r in every if _stable(r)]
        iso = [r for r in mine if r["path"] in ISOTROPIC_PATHS]
        ratios = np.array([r["ratio"] for r in iso])
        at = {r["state"]: r for r in mine}

        def get(label, key, at=at):
            return at[label][key] if label in at else math.nan

        exponent = math.nan
        positive = [r for r in iso if r["p"] > 0 and r["e_v"] > 0]
        if len(positive) >= 2:
            lp = np.log([r["p"] for r in positive])
            le = np.log([r["e_v"] for r in positive])
            exponent = float(np.polyfit(lp, le, 1)[0]) if np.ptp(lp) > 0 else math.nan
        out[n] = dict(
            iso_mean=float(ratios.mean()) if ratios.size else math.nan,
            iso_sd=float(ratios.std(ddof=1)) if ratios.size > 1 else math.nan,
            iso_n=int(ratios.size),
            ratio_C=get("C", "ratio"),
            ratio_B=get("B", "ratio"),
            ratio_Bp=get("B'", "ratio"),
            ev_over_p_B=get("B", "e_v") / get("B", "p"),
            exponent=exponent,
            unstable=len(every) - len(mine),
        )
    return out


def figure(rows: list[dict], path: Path) -> None:
    """E_h/E_v against κ_b/(k_n d²) (rigid at the right) for every state; two panels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    states = list(dict.fromkeys(r["state"] for r in rows))
    rigid_x = 3.0
    for ax, family, title in (
        (axes[0], "chain", "chains: k_bn = k_n, k_bt = k_t"),
        (axes[1], "bend", "bending only: k_bn = k_bt = 1e6 k_n"),
    ):
        k0 = [s for s in states if any(r["state"] == s and r["path"] in ("A_to_C",) for r in rows)]
        cmap = plt.get_cmap("viridis")
        for s in states:
            mine = [r for r in rows if r["state"] == s and r["family"] == family and _stable(r)]
            rigid = [r for r in rows if r["state"] == s and r["variant"] == "rigid"]
            if not mine:
                continue
            points = sorted((r["kappa_b"], r["ratio"]) for r in mine) + [
                (rigid_x, rigid[0]["ratio"])
            ]
            x, y = zip(*points, strict=True)
            kind = mine[0]["path"]
            if kind in ISOTROPIC_PATHS:
                style = dict(
                    color="0.6", ls="--", lw=1, label="isotropic path" if s == "A" else None
                )
            elif kind == "A_to_C":
                style = dict(
                    color=cmap(k0.index(s) / max(len(k0) - 1, 1)),
                    lw=1.6,
                    label=s if s == "C" or s.endswith("_1") else None,
                )
            else:
                style = dict(color="tab:red", lw=1, ls=":", label="C→B′" if s == "B'" else None)
            ax.plot(x, y, marker="o", ms=3, **style)
        ax.axhline(1.0, color="k", lw=0.6)
        ax.set_xscale("log")
        ax.set_xticks(list(KAPPAS) + [rigid_x])
        ax.set_xticklabels([f"{k:g}" for k in KAPPAS] + ["∞"])
        ax.set_xlabel("bending stiffness κ_b / (k_n d²)")
        ax.set_title(title, fontsize=10)
        ax.legend(fontsize=7)
    axes[0].set_ylabel("E_oed,h / E_oed,v (linear response)")
    fig.suptitle("Frozen networks: does rod bending turn E_h/E_v above 1? (K0 states A→C coloured)")
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def run_matrix(
    run_dir: Path,
    out_dir: Path,
    relax_ufr: float | None = None,
    dynamic_states: tuple[str, ...] = (),
    amplitudes: tuple[float, ...] = (),
    progress: bool = True,
) -> tuple[list[dict], list[dict]]:
    """The whole matrix on one run directory; writes csv, md and png into ``out_dir``."""
    files = state_files(run_dir)
    if not files:
        raise SystemExit(f"error: no state_*.npz or path_*.npz in {run_dir}")
    rows, dyn = [], []
    variant_list = None
    for label, path, increment, f in files:
        t0 = time.perf_counter()
        sim, info = relaxed_sim(f, relax_ufr)
        snap = sim.snapshot()
        if variant_list is None:
            d = snap.diameter
            variant_list = variants(snap.k_n, snap.k_t, d)
        state_rows = matrix_rows(label, path, increment, snap, sim.measure(), variant_list)
        for r in state_rows:
            r.update(info)
        rows += state_rows
        if label in dynamic_states:
            dyn += dynamic_rows(label, sim, amplitudes)
        if progress:
            chain = next(r["ratio"] for r in state_rows if r["variant"] == "chain_kb0.1")
            print(
                f"{label:>12}: rigid E_h/E_v {state_rows[0]['ratio']:.3f}, chain κ=0.1 "
                f"{chain:.3f} ({time.perf_counter() - t0:.1f} s)",
                flush=True,
            )
    out_dir.mkdir(parents=True, exist_ok=True)
    base = out_dir / "stiffness_anisotropy_matrix"
    with open(base.with_suffix(".csv"), "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    if dyn:
        with open(out_dir / "stiffness_anisotropy_dynamic.csv", "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(dyn[0]))
            writer.writeheader()
            writer.writerows(dyn)
    base.with_suffix(".md").write_text(markdown(rows, dyn, run_dir))
    figure(rows, base.with_suffix(".png"))
    return rows, dyn


def _floats(text: str) -> tuple[float, ...]:
    return tuple(float(x) for x in text.split(",") if x.strip())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run_dir", type=Path, help="output folder of a protocol run")
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results"))
    parser.add_argument(
        "--relax-ufr",
        type=float,
        default=None,
        help="relax each state further at fixed cell to this UFR first",
    )
    parser.add_argument("--dynamic-states", default="", help='e.g. "C,B\'"')
    parser.add_argument("--amplitudes", default="1e-7,1e-6,1e-5,1e-4")
    args = parser.parse_args(argv)
    if not args.run_dir.is_dir():
        parser.error(f"{args.run_dir} is not a directory")
    dynamic = tuple(s.strip() for s in args.dynamic_states.split(",") if s.strip())
    t0 = time.perf_counter()
    rows, _ = run_matrix(args.run_dir, args.out, args.relax_ufr, dynamic, _floats(args.amplitudes))
    print(f"{len(rows)} rows in {time.perf_counter() - t0:.0f} s -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
