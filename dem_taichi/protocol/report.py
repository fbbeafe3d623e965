"""Markdown report and figures of a protocol run (:func:`dem_taichi.protocol.runner.run_protocol`).

The report lists the stages with their wall times and quasi-static indicators, the states A, B,
C, B', R<k>_end with p, q, v, fabric and the moduli of both probing methods, the fluid–solid
transition rule and values, and findings with numbers: fabric isotropy along A→B against the
sampling noise sqrt(0.5/N), E_oed,h/E_oed,v along A→B and A→C, the ln v – ln p slope beyond A,
and the agreement of the two probing methods.

Symbols: p, q (DEM stress units, force/length; kPa = DEM × stress_scale_kpa), v specific volume,
β_yy − β_xx fabric deviator, E_oed,v, E_oed,h constrained moduli, λ* = −d ln v / d ln p.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from dem_taichi.analysis.arrays import (
    FABRIC_NOISE_MULTIPLE,
    PathArrays,
    ProbeArrays,
    compressibility_slope,
    fabric_isotropy,
    max_change,
    methods_relative_difference,
    stiffness_ratio,
    stress_ratio_at,
)
from dem_taichi.analysis.findings import findings_from_arrays
from dem_taichi.engine.work_profile import work_rows

__all__ = ["write_figures", "write_report", "findings", "compressibility_slope"]


def path_arrays(result) -> PathArrays:
    """The relaxed states of a :class:`~dem_taichi.protocol.records.ProtocolResult` as the
    arrays the findings read (:class:`~dem_taichi.analysis.arrays.PathArrays`), the same arrays
    :func:`dem_taichi.analysis.findings.path_arrays` reads from the run's files."""
    states = {label: s.measures for label, s in result.states.items()}
    stage = np.array([str(s.stage) for s in result.path_states], dtype=str)
    names = set(result.path_states[0].measures) if result.path_states else set()
    measures = {
        name: np.array([float(s.measures.get(name, math.nan)) for s in result.path_states])
        for name in names
        if all(_is_number(s.measures.get(name)) for s in result.path_states)
    }
    return PathArrays(states, stage, measures)


def probe_arrays(result) -> ProbeArrays:
    """The probes of a :class:`~dem_taichi.protocol.records.ProtocolResult` as
    :class:`~dem_taichi.analysis.arrays.ProbeArrays` (what ``probes.nc`` holds)."""
    probes = result.probes
    if not probes:
        return ProbeArrays.empty()

    def moduli(name: str, method: str) -> np.ndarray:
        return np.array([float(pr.modulus(name, method)) for pr in probes])

    return ProbeArrays(
        label=np.array([str(pr.label) for pr in probes], dtype=str),
        path=np.array([str(pr.path) for pr in probes], dtype=str),
        mean_stress=np.array([float(pr.measures["mean_stress"]) for pr in probes]),
        e_oed_v=moduli("e_oed_v", "linear"),
        e_oed_h=moduli("e_oed_h", "linear"),
        e_oed_v_dynamic=moduli("e_oed_v", "dynamic"),
        e_oed_h_dynamic=moduli("e_oed_h", "dynamic"),
    )


def _is_number(value) -> bool:
    return isinstance(value, int | float | np.number) and not isinstance(value, bool)


def findings(result) -> dict:
    """Numbers of the study's findings from a :class:`~dem_taichi.protocol.runner.ProtocolResult`.

    Each finding is computed by the functions of :mod:`dem_taichi.analysis.arrays` over the run's
    arrays (:func:`path_arrays`, :func:`probe_arrays`), the functions that
    :func:`dem_taichi.analysis.findings.run_findings` calls on the run's files.
    """
    path, probes = path_arrays(result), probe_arrays(result)
    out: dict = {}
    iso_fabric = path.from_a("A_to_B", "fabric_deviator")
    fabric = fabric_isotropy(iso_fabric, result.n_rods)
    out["fabric_noise"] = fabric.noise
    if iso_fabric.size:
        out["isotropic_fabric_max_abs"] = fabric.max_abs
        out["isotropic_fabric_within_noise"] = fabric.within_noise
        out["isotropic_compressibility"] = compressibility_slope(
            path.from_a("A_to_B", "mean_stress"), path.from_a("A_to_B", "specific_volume")
        )
    k0_p = path.on("A_to_C", "mean_stress")
    if k0_p.size:
        out["k0_fabric"] = [
            (float(p), float(b))
            for p, b in zip(k0_p, path.on("A_to_C", "fabric_deviator"), strict=True)
        ]
        out["k0_strain_xx_max_change"] = max_change(
            path.on("A_to_C", "strain_xx"), path.at("A", "strain_xx")
        )
        out["k0_stress_ratio_end"] = stress_ratio_at(path, "C")
    cb_p = path.on("C_to_B", "mean_stress")
    if cb_p.size and "C" in path.states:
        p_c = path.at("C", "mean_stress")
        out["unloading_max_relative_p_change"] = max_change(cb_p, p_c) / p_c
    by_method = {
        method: stiffness_ratio(e_h, e_v)
        for method, (e_v, e_h) in (
            ("dynamic", (probes.e_oed_v_dynamic, probes.e_oed_h_dynamic)),
            ("linear", (probes.e_oed_v, probes.e_oed_h)),
        )
    }
    ratios: dict[str, list[tuple[str, str, float, float]]] = {}
    # the methods in the order their first ratio appears among the probes (the report's lines)
    for method, ratio in sorted(
        ((m, r) for m, r in by_method.items() if np.isfinite(r).any()),
        key=lambda item: int(np.flatnonzero(np.isfinite(item[1]))[0]),
    ):
        ratios[method] = [
            (str(probes.label[i]), str(probes.path[i]), float(probes.mean_stress[i]),
             float(ratio[i]))
            for i in np.flatnonzero(np.isfinite(ratio))
        ]  # fmt: skip
    out["anisotropy_ratio"] = ratios
    agreement = methods_relative_difference(probes)
    if agreement.size:
        out["methods_max_relative_difference"] = float(np.max(agreement))
        out["methods_median_relative_difference"] = float(np.median(agreement))
    return out


def write_figures(result, geometry) -> dict[str, str]:
    """Figures 1 and 2 of the study from the files of a run; returns {name: path}."""
    from dem_taichi.analysis.figures import figure_paths, figure_states
    from dem_taichi.io import open_configuration, open_history, open_probes

    out = Path(result.out_dir)
    files: dict[str, str] = {}
    relaxed = open_history(out / "relaxed_states.nc")
    configurations = {}
    for label in result.states:
        key = f"configuration_{label}"
        if key in result.files:
            configurations[label] = open_configuration(result.files[key])
    geo = {"n_spheres": geometry.n_spheres, "spacing": geometry.spacing,
           "diameter": geometry.diameter}  # fmt: skip
    files["figure_paths"] = str(
        # relaxed (quasi-static) path states; loading records with their dynamic stress
        # fluctuations stay in history.nc
        figure_paths(relaxed, configurations, out / "figure_paths.png", geo)
    )
    probes = open_probes(result.files["probes"]) if "probes" in result.files else None
    files["figure_states"] = str(figure_states(relaxed, probes, out / "figure_states.png"))
    return files


def _fmt(value, digits: int = 4) -> str:
    if value is None:
        return "—"
    try:
        value = float(value)
    except (TypeError, ValueError):
        return str(value)
    if not math.isfinite(value):
        return "—"
    return f"{value:.{digits}g}"


def _work_lines(result) -> list[str]:
    """The section 'Where the steps go' (:mod:`dem_taichi.engine.work_profile`): steps and seconds
    by stage and kind of work; empty when the run kept no ledger."""
    log = getattr(result, "log", None)
    ledger = getattr(log, "work", None)
    if not ledger:
        return []
    rows = work_rows(ledger, {k: v.seconds for k, v in result.stages.items()})
    lines = [
        "",
        "## Where the steps go",
        "",
        "Work labels: the quasi-static block (strain, relax, hold) inside what asked for it "
        "(servo, probe, search/confirm of state A); overhead = the stage's wall time outside the "
        "step kernels and the measures (Python between launches, state copies, the servo's "
        "algebra, file writes). Probes run under the stage 'probe'.",
        "",
        "| stage | work | steps | share of the stage's steps | kernel (s) | measures (s) "
        "| overhead (s) | steps per kernel s | calls |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if r["work"] == "overhead":
            lines.append(f"| {r['stage']} | overhead | | | | | {r['overhead_seconds']:.1f} | | |")
            continue
        lines.append(
            f"| {r['stage']} | {r['work']} | {r['steps']} | {100 * r['share_of_steps']:.0f}% | "
            f"{r['kernel_seconds']:.1f} | {r['measure_seconds']:.1f} | | "
            f"{_fmt(r['steps_per_kernel_second'], 3)} | {r['calls']} |"
        )
    return lines


def write_report(
    result, path: Path | None = None, rod_shape: tuple[int, float, float] | None = None
) -> Path:
    """Write ``report.md`` of a run (see the module docstring); returns its path. ``rod_shape``
    (n_spheres, spacing, diameter) gives N under the rod-rectangle definition (NaN without)."""
    out = Path(result.out_dir)
    path = path or out / "report.md"
    scale = result.stress_scale_kpa
    lines = [
        f"# DEM virtual experiments: scene `{result.scene_name}`, pattern `{result.pattern}`",
        "",
        f"{result.n_rods} rods; arch {result.arch}, precision {result.precision}; total wall time "
        f"{result.total_seconds:.1f} s (probing {result.probing_seconds:.1f} s: dynamic "
        f"{result.probing_dynamic_seconds:.1f} s, linear response "
        f"{result.probing_linear_seconds:.2f} s). Stresses in DEM units (force/length, "
        f"compression positive); one DEM stress unit = {scale:g} kPa.",
        "",
        "## Stages",
        "",
        *(
            [
                f"The paths from A ran in {result.workers} processes at once (--workers "
                f"{result.workers}): their stage times overlap, so the shares add up to more "
                "than 100 %.",
                "",
            ]
            if getattr(result, "workers", 1) > 1
            else []
        ),
        "| stage | wall time (s) | share | steps | relaxed states | servo corrections | max I "
        "| max UFR loading | max UFR relaxed |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    total = max(result.total_seconds, 1e-12)
    for name, st in result.stages.items():
        lines.append(
            f"| {name} | {st.seconds:.1f} | {100 * st.seconds / total:.0f}% | {st.steps} | "
            f"{st.n_relaxed_states} | {st.servo_iterations} | {_fmt(st.max_inertial_number, 3)} | "
            f"{_fmt(st.max_unbalanced_force_loading, 3)} | "
            f"{_fmt(st.max_unbalanced_force_relaxed, 3)} |"
        )
    lines.append(
        f"| probing | {result.probing_seconds:.1f} | {100 * result.probing_seconds / total:.0f}% "
        "| | | | | | |"
    )
    lines += _work_lines(result)
    t = result.transition_details
    lines += [
        "",
        "## Fluid–solid transition (state A)",
        "",
        f"Rule: {t.get('rule', '—')}.",
        "",
        f"p_A = {_fmt(t.get('mean_stress'))} (previous relaxed state: "
        f"{_fmt(t.get('mean_stress_before'))}); Z_m at A = "
        f"{_fmt(t.get('mechanical_coordination_number'))}, jump {_fmt(t.get('coordination_jump'))}"
        f"; v_A = {_fmt(t.get('specific_volume'), 5)}; {t.get('n_increments', '—')} compression "
        f"increments; detector index {t.get('detector_index')} vs protocol "
        f"{t.get('protocol_index')} (agree: {t.get('detector_agrees')}).",
        "",
        "## States",
        "",
        "| state | path | p | q | p (kPa) | v | β_yy−β_xx | Z_m | E_v dyn | E_v lin | E_h dyn "
        "| E_h lin | E_h/E_v lin | K lin | G lin |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    probes_by_label = {p.label: p for p in result.probes}
    for label, s in result.states.items():
        m = s.measures
        pr = probes_by_label.get(label)
        ev_d = pr.modulus("e_oed_v", "dynamic") if pr else math.nan
        ev_l = pr.modulus("e_oed_v", "linear") if pr else math.nan
        eh_d = pr.modulus("e_oed_h", "dynamic") if pr else math.nan
        eh_l = pr.modulus("e_oed_h", "linear") if pr else math.nan
        k_l = pr.linear.bulk_modulus if pr is not None and pr.linear is not None else math.nan
        g_l = (
            pr.linear.voigt_shear_modulus if pr is not None and pr.linear is not None else math.nan
        )
        lines.append(
            f"| {label} | {s.stage} | {_fmt(m['mean_stress'])} | {_fmt(m['deviatoric_stress'])} | "
            f"{_fmt(m['mean_stress'] * scale)} | {_fmt(m['specific_volume'], 5)} | "
            f"{m['fabric_deviator']:+.4f} | {_fmt(m['mechanical_coordination_number'])} | "
            f"{_fmt(ev_d)} | {_fmt(ev_l)} | {_fmt(eh_d)} | {_fmt(eh_l)} | "
            f"{_fmt(eh_l / ev_l if ev_l else math.nan, 3)} | {_fmt(k_l)} | {_fmt(g_l)} |"
        )
    if result.probes:
        lines += [
            "",
            "## All probes",
            "",
            "| probe | path | p | v | β_yy−β_xx | E_v dyn | E_v lin | E_h dyn | E_h lin | "
            "E_h/E_v dyn | E_h/E_v lin | elastic limit v/h | dyn s | lin s | base Δσ/p |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        ]
        for pr in result.probes:
            m = pr.measures
            ev_d, ev_l = pr.modulus("e_oed_v", "dynamic"), pr.modulus("e_oed_v", "linear")
            eh_d, eh_l = pr.modulus("e_oed_h", "dynamic"), pr.modulus("e_oed_h", "linear")
            lim = "/".join(
                _fmt(pr.curves[a].plateau.elastic_limit, 2) if a in pr.curves else "—"
                for a in ("y", "x")
            )
            lines.append(
                f"| {pr.label} | {pr.path} | {_fmt(m['mean_stress'])} | "
                f"{_fmt(m['specific_volume'], 5)} | {m['fabric_deviator']:+.4f} | {_fmt(ev_d)} | "
                f"{_fmt(ev_l)} | {_fmt(eh_d)} | {_fmt(eh_l)} | "
                f"{_fmt(eh_d / ev_d if ev_d else math.nan, 3)} | "
                f"{_fmt(eh_l / ev_l if ev_l else math.nan, 3)} | {lim} | "
                f"{pr.dynamic_seconds:.1f} | {pr.linear_seconds:.3f} | "
                f"{pr.base_stress_change:.1e} |"
            )
        lines += [
            "",
            "Probes are made on a copy of the path state relaxed further to the probes' UFR "
            "threshold; base Δσ/p is the largest stress change of that relaxation.",
            "",
            "Degradation curves (secant E against amplitude):",
            "",
        ]
        for pr in result.probes:
            for axis, curve in pr.curves.items():
                pts = ", ".join(
                    f"{a:.0e}: {_fmt(e, 5)}"
                    for a, e in zip(curve.amplitudes, curve.moduli, strict=True)
                )
                lines.append(
                    f"- {pr.label} {axis}: {pts} (plateau {_fmt(curve.plateau.modulus, 5)})"
                )
    f = findings(result)
    lines += ["", "## Findings", ""]
    if "isotropic_fabric_max_abs" in f:
        lines.append(
            f"- Isotropic path (A and A→B): max |β_yy−β_xx| = {f['isotropic_fabric_max_abs']:.4f} "
            f"against the sampling noise sqrt(0.5/N) = {f['fabric_noise']:.4f} "
            f"(within {FABRIC_NOISE_MULTIPLE:g} noise: {f['isotropic_fabric_within_noise']})."
        )
        c = f["isotropic_compressibility"]
        lines.append(
            f"- ln v – ln p along A→B: λ* = {_fmt(c['lambda_star'])}, R² = {_fmt(c['r2'])} "
            f"over {c['n']} relaxed states."
        )
    if "k0_fabric" in f:
        pts = ", ".join(f"p={_fmt(p, 3)}: {b:+.4f}" for p, b in f["k0_fabric"])
        lines.append(f"- K0 path fabric deviator: {pts} (negative = rods lying down).")
        lines.append(
            f"- K0: max |ε_xx − ε_xx(A)| = {f['k0_strain_xx_max_change']:.3g}; "
            f"K0 = σ_xx/σ_yy at C = {f['k0_stress_ratio_end']:.3f}."
        )
    if "unloading_max_relative_p_change" in f:
        lines.append(
            "- C→B: max |p − p_C|/p_C at relaxed states = "
            f"{f['unloading_max_relative_p_change']:.2e}."
        )
    for method, rows in f.get("anisotropy_ratio", {}).items():
        pts = ", ".join(f"{lab} ({path}, p={_fmt(p, 3)}): {r:.3f}" for lab, path, p, r in rows)
        lines.append(f"- E_oed,h/E_oed,v ({method}): {pts}.")
    if "methods_max_relative_difference" in f:
        lines.append(
            "- Dynamic plateau vs linear response: max relative difference "
            f"{f['methods_max_relative_difference']:.3f}, median "
            f"{f['methods_median_relative_difference']:.3f}."
        )
    lines += _window_lines(result, rod_shape)
    lines += ["", "## Files", ""]
    for name, file in result.files.items():
        lines.append(f"- {name}: `{file}`")
    path.write_text("\n".join(lines) + "\n")
    return path


def _window_lines(result, rod_shape: tuple[int, float, float] | None) -> list[str]:
    """The report's section on the study's stress window (issue 19): the findings of
    :func:`~dem_taichi.analysis.findings.mapped_window_findings` over the run's arrays; no
    section for a run without A→B."""
    if not result.path_states or "A" not in result.states:
        return []
    try:
        w = findings_from_arrays(
            path_arrays(result), probe_arrays(result), result.n_rods, result.stress_scale_kpa,
            rod_shape,
        )  # fmt: skip
    except Exception as exc:  # noqa: BLE001 - the report must not lose a finished run
        return ["", "## On the study's stress window", "", f"- Not computed: {exc}"]
    if math.isfinite(w["stress_scale_kpa_measured"]):
        scale = (
            f"{_fmt(w['stress_scale_kpa_measured'])} kPa per DEM unit (E_oed,v/p falls through "
            f"125 at p* = {_fmt(w['p_star'])} DEM units, which stands for 100 kPa)"
        )
    else:
        scale = f"not measured: {w['stress_scale_reason']}"
    local = ", ".join(
        f"{_fmt(p, 3)}: {_fmt(x, 3)}"
        for p, x in zip(w["local_lambda_p_kpa"], w["local_lambda"], strict=True)
    )
    return [
        "",
        "## On the study's stress window",
        "",
        f"- Stress scale by the stiffness: {scale}; used below: "
        f"{_fmt(w['stress_scale_kpa_used'])} kPa per DEM unit ({w['stress_scale_source']}).",
        f"- λ* over 1–200 kPa: {_fmt(w['lambda_window'])} ± {_fmt(w['lambda_window_se'], 2)} "
        f"(standard error, {w['n_window_points']} states); the study: 0.25.",
        f"- E_oed ∝ p^n over 1–200 kPa: n = {_fmt(w['exponent_window_v'], 3)} (vertical), "
        f"{_fmt(w['exponent_window_h'], 3)} (horizontal), {w['n_exponent_points']} probes; "
        "the study: n + r = 0.80.",
        f"- N (v at 100 kPa along A→B): {_fmt(w['N_disc'])} with the disc-union rod area, "
        f"{_fmt(w['N_rectangle'])} with the rod rectangle L × d; the study: 1.30.",
        "- Densification sensitivity ln(E_B′/E_B)/ln(v_B′/v_B): "
        f"{_fmt(w['densification_sensitivity_v'], 3)} (E_oed,v), "
        f"{_fmt(w['densification_sensitivity_h'], 3)} (E_oed,h); Table 1 implies ≈ −2.5.",
        f"- Local λ* = −d ln v/d ln p along A→B (p in kPa: λ*): {local or '—'}.",
    ]
