"""MkDocs hooks of the documentation site (``mkdocs.yml``: ``hooks: [docs/hooks.py]``).

What the site shows that is not a file under ``docs/``:

- ``reference/scene.md``: every key of every scene section, generated from the sections' field
  metadata (type, default, allowed range or choices, unit, description;
  :mod:`dem_taichi.scene.base`), so it cannot drift from the code;
- ``reference/results-files.md``: every variable of the results files, generated from the schema
  tables (:mod:`dem_taichi.io.schema`, :data:`tiv_model.drivers.VARIABLES`, the bridge's and the
  sweeps' tables);
- ``project/architecture.md`` and ``project/changelog.md``: the repository's ``ARCHITECTURE.md``
  and ``CHANGELOG.md``, read where they are (not copied);
- ``results/files/<path>``: every file under ``benchmarks/results/`` (``.md`` files as pages,
  the others, CSV, PNG, JSON…, as they are), so a results page links ``files/<name>.md``;
- the nav entry "Results and validation": every ``docs/results/*.md``, ``index.md`` first, so a
  new results page needs no edit of ``mkdocs.yml``.

Links inside the exposed repository files are rewritten for the site: ``docs/<page>`` to the
page, ``benchmarks/results/<file>`` to ``results/files/<file>``, other repository paths to plain
code text (the site has no copy of the source tree); a link of an exposed results file to a file
that does not exist (a figure not committed) becomes plain text instead of a broken link.

The generators (:func:`scene_reference`, :func:`results_files_reference`) are plain functions:
``tests/test_docs.py`` imports this file and checks their output against the dataclasses.
"""

from __future__ import annotations

import dataclasses
import posixpath
import re
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
RESULTS = ROOT / "benchmarks" / "results"

#: site path -> repository file shown there
PROJECT_FILES = {
    "project/architecture.md": ROOT / "ARCHITECTURE.md",
    "project/changelog.md": ROOT / "CHANGELOG.md",
}
SCENE_REFERENCE = "reference/scene.md"
RESULTS_REFERENCE = "reference/results-files.md"
RESULTS_FILES = "results/files"
RESULTS_NAV_TITLE = "Results and validation"

# ------------------------------------------------------------------------------------------
# The scene reference
# ------------------------------------------------------------------------------------------


def scene_sections() -> dict[str, type]:
    """Section name -> dataclass of every section a scene may have (core, then extensions)."""
    from dem_taichi.scene import config

    return {**config._CORE_SECTIONS, **config._EXTENSION_SECTIONS}


def _type_name(f: dataclasses.Field) -> str:
    kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
    kind = kind.replace(" | None", "")
    return {"str": "list" if f.metadata.get("list") else "string", "bool": "boolean"}.get(
        kind, kind
    )


def _toml(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace('"', '\\"') + '"'
    return repr(value)


def field_default(f: dataclasses.Field) -> str:
    """The default of a field as a TOML value, ``unset`` for an optional key without one."""
    if f.default is dataclasses.MISSING:
        return "required"
    if f.default is None:
        return "unset"
    return _toml(f.default)


def _number(value: Any) -> str:
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e6:
        return repr(value)
    return f"{value:g}" if isinstance(value, float) else f"{value:,}".replace(",", "_")


def field_allowed(f: dataclasses.Field) -> str:
    """The allowed values of a field: its range, choices, a list, or its type's values."""
    meta = f.metadata
    if "choices" in meta:
        return " | ".join(f"`{_toml(c)}`" for c in meta["choices"])
    if "range" in meta:
        lo, hi, lo_open, hi_open = meta["range"]
        left = "(" if (lo_open or lo is None) else "["
        right = ")" if (hi_open or hi is None) else "]"
        low = "−∞" if lo is None else _number(lo)
        high = "∞" if hi is None else _number(hi)
        return f"{left}{low}, {high}{right}"
    if meta.get("list"):
        return "TOML array or comma-separated string"
    if _type_name(f) == "boolean":
        return "true | false"
    return "any text"


def _cell(text: str) -> str:
    """Text for a Markdown table cell: no line breaks, pipes escaped, ``<``/``>`` as entities."""
    text = " ".join(str(text).split())
    return text.replace("|", "\\|").replace("<", "&lt;").replace(">", "&gt;")


def scene_rows(cls: type) -> list[dict[str, str]]:
    """One row per key of the section dataclass ``cls``: key, type, default, allowed, unit, doc."""
    rows = []
    for f in dataclasses.fields(cls):
        optional = " (optional)" if f.metadata.get("optional") else ""
        rows.append(
            {
                "key": f.name,
                "type": _type_name(f) + optional,
                "default": field_default(f),
                "allowed": field_allowed(f),
                "unit": f.metadata.get("unit", ""),
                "doc": f.metadata.get("doc", ""),
            }
        )
    return rows


def _first_paragraph(doc: str | None) -> str:
    """The first paragraph of a docstring, its reST roles and ``literals`` as Markdown."""
    if not doc:
        return ""
    text = " ".join(doc.strip().split("\n\n")[0].split())
    text = re.sub(r":(?:py:)?[a-z]+:`~?\.?([^`]+)`", r"`\1`", text)
    text = re.sub(r"``([^`]+)``", r"`\1`", text)
    # a cited docs page (docs/science/dem-model.md §1.7) as a link from reference/
    return re.sub(r"(?<![`\w/])docs/([\w/-]+\.md)(?![`\w])", r"[\g<0>](../\1)", text)


def _presets_table() -> list[str]:
    from dem_taichi.scene.presets import PRESETS

    names = list(PRESETS)
    keys = list(dict.fromkeys(k for p in PRESETS.values() for k in p))
    lines = [
        "| key | " + " | ".join(f"`{n}`" for n in names) + " |",
        "|---|" + "---|" * len(names),
    ]
    for key in keys:
        values = " | ".join(f"`{_toml(PRESETS[n].get(key, ''))}`" for n in names)
        lines.append(f"| `{key}` | {values} |")
    return lines


def scene_reference() -> str:
    """The Markdown of ``reference/scene.md``."""
    from dem_taichi.scene.config import _RETIRED_KEYS

    lines = [
        "# Scene keys",
        "",
        "<!-- generated by docs/hooks.py from the field metadata of the scene sections "
        "(dem_taichi/scene/sections.py, dem_taichi/scene/protocol_sections.py with "
        "dem_taichi/scene/aggregation_keys.py and dem_taichi/scene/servo_keys.py, "
        "dem_taichi/scene/probing_sections.py): "
        "do not edit -->",
        "",
        "A scene is a TOML file with one table per section; every key is optional and takes the "
        "default below when a file leaves it out (a scene *file* must have a `[particles]` "
        "table). Keys are checked at load: an unknown key or section, a value of the wrong type "
        "or outside its allowed values fails with an error naming the key and what is allowed. "
        "The same keys are set on the command line with `--set section.key=value` and in sweeps "
        "as `section.key`.",
        "",
        "**Units.** DEM units: the disc diameter d = 1 is the unit of length, the disc mass "
        "m = 1 the unit of mass, and the scene's time unit the unit of time; a 2D stiffness "
        "and a 2D stress are forces per length. `1` is a dimensionless number, `steps` a number "
        "of time steps, `-` a text or a switch.",
        "",
        "**Allowed.** `[a, b]` includes the bounds, `(a, b)` excludes them; `∞` is unbounded. "
        "Every number of a scene is also limited to magnitudes 1e-12 to 1e12 (or 0). "
        "*Optional* keys are written to a scene's TOML only when set; `unset` means the "
        "behaviour the description gives.",
        "",
        "This page is generated from the code (`docs/hooks.py`); the sections are the dataclasses "
        "of `dem_taichi.scene.sections`, `dem_taichi.scene.interaction_sections`, "
        "`dem_taichi.scene.protocol_sections` and `dem_taichi.scene.probing_sections`.",
        "",
    ]
    for name, cls in scene_sections().items():
        lines += [f"## [{name}]", ""]
        summary = _first_paragraph(cls.__doc__)
        generic = (
            summary.startswith(cls.__name__ + "(")  # the dataclass's generated signature
            or not summary
        )
        if not generic:
            lines += [summary, ""]
        lines += [
            f"Dataclass `{cls.__module__}.{cls.__name__}`.",
            "",
            "| key | type | default | allowed | unit | description |",
            "|---|---|---|---|---|---|",
        ]
        for row in scene_rows(cls):
            lines.append(
                f"| `{row['key']}` | {_cell(row['type'])} | `{_cell(row['default'])}` | "
                f"{_cell(row['allowed'])} | {_cell(row['unit'])} | {_cell(row['doc'])} |"
            )
        retired = _RETIRED_KEYS.get(name, ())
        if retired:
            lines += [
                "",
                "Retired keys, accepted and dropped at load (older scenes and checkpoints): "
                + ", ".join(f"`{k}`" for k in retired)
                + ".",
            ]
        lines.append("")
    lines += [
        "## Presets",
        "",
        "`[scene] preset` (and `--preset NAME` on the command line) sets these keys "
        "(`dem_taichi.scene.presets`): in a file, the keys the file gives win; on the command line "
        "the preset's keys replace the scene's and `--set` wins.",
        "",
        *_presets_table(),
        "",
    ]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------
# The results-files reference
# ------------------------------------------------------------------------------------------


def _variable_table(variables) -> list[str]:
    lines = [
        "| variable | dimensions | type | units | DEM units | meaning | definition |",
        "|---|---|---|---|---|---|---|",
    ]
    for v in variables:
        notes = v.definition
        if v.sign_convention:
            notes = f"{notes} ({v.sign_convention.replace('_', ' ')})".strip()
        if v.flag_meanings:
            pairs = zip(v.flag_values, v.flag_meanings, strict=True)
            flags = ", ".join(f"{c} {m}" for c, m in pairs)
            notes = f"{notes}; flags: {flags}".strip("; ")
        dims = ", ".join(v.dims) or "scalar"
        lines.append(
            f"| `{v.name}` | {_cell(dims)} | {v.dtype} | `{_cell(v.units)}` | "
            f"{_cell(v.dem_units or '')} | {_cell(v.long_name)} | {_cell(notes)} |"
        )
    return lines


def _pairs_table(table, dims: str, prefix: str = "") -> list[str]:
    lines = ["| variable | dimensions | units | meaning |", "|---|---|---|---|"]
    for name, (units, long_name) in table.items():
        lines.append(f"| `{prefix}{name}` | {dims} | `{_cell(units)}` | {_cell(long_name)} |")
    return lines


def results_files_reference() -> str:
    """The Markdown of ``reference/results-files.md``."""
    from bridge.predict import _UNITS as PREDICTION_UNITS
    from bridge.runs import RUN_VARIABLES
    from bridge.series import SERIES_VARIABLES
    from dem_taichi.analysis.findings import STATE_MEASURES
    from dem_taichi.io.history_schema import BONDED_HISTORY_VARIABLES
    from dem_taichi.io.schema import (
        CONFIGURATION_VARIABLES,
        DEM_UNIT_SYSTEM,
        HISTORY_VARIABLES,
        PROBE_VARIABLES,
        STAGE_CODES,
    )
    from dem_taichi.sweep.results import RUN_SCALARS
    from tiv_model.drivers import VARIABLES as TIV_VARIABLES

    prediction = {
        name: SERIES_VARIABLES.get(name) or PREDICTION_UNITS[name] for name in RUN_VARIABLES
    }
    lines = [
        "# Results files",
        "",
        "<!-- generated by docs/hooks.py from the schema tables of dem_taichi.io, "
        "tiv_model.drivers, bridge and dem_taichi.sweep.results: do not edit -->",
        "",
        "Every variable of every netCDF file the project writes, from the tables the writers "
        "use (`dem_taichi.io.schema` for the DEM files), so this page cannot drift from the "
        "files. The DEM files follow CF-1.11; their global attributes carry the provenance "
        "(package version, git hash, the scene's full TOML, Taichi version, arch, precision, "
        "seed) and the unit system.",
        "",
        "## Units of the DEM files",
        "",
        DEM_UNIT_SYSTEM + ".",
        "",
        'A DEM quantity is stored with `units = "1"` and its DEM dimension in the attribute '
        "`dem_units` (column *DEM units*); angles are in radians. Stresses are compression "
        'positive (`sign_convention = "compression_positive"`), p = (σ_xx + σ_yy)/2 and '
        "q = σ_yy − σ_xx in 2D; strains are logarithmic, compression positive.",
        "",
        "## A protocol run directory",
        "",
        "`python -m dem_taichi protocol SCENE --out DIR` (or `dem_taichi.run_protocol`) writes "
        "these (`python -m dem_taichi run`, the built-in run, writes `run.json`, `scene.toml`, "
        "`history.nc` and `checkpoints/`):",
        "",
        "| file | what |",
        "|---|---|",
        "| `run.json` | the run id, the scene's SHA-256 and the manifest of every file and "
        "folder the run wrote |",
        "| `scene.toml` | the scene as run (every key, defaults included) |",
        "| `history.nc` | one record per output step along the unlimited dimension `time` "
        "(CDF5, appended and synced as the run goes: a killed run leaves a readable file) |",
        "| `relaxed_states.nc` | the same variables, one record per relaxed state of the paths "
        "(the states the findings are computed from) |",
        "| `probes.nc` | the elastic probes: one entry per probed state along `probe` |",
        "| `configuration_*.nc` | the rods and the cell at each labelled state "
        "(`configuration_A.nc`, …) |",
        "| `summary.json`, `report.md`, `figure_*.png` | the run's findings, its report and "
        "figures |",
        "| `state_*.npz` | checkpoints at the labelled states (`[protocol] save_states`) |",
        "| `path_*.npz` | checkpoints at every relaxed increment of the paths "
        "(`[protocol] save_path_states`) |",
        "| `checkpoints/` | the built-in run's checkpoints (`dem_taichi run`), for `--resume` |",
        "| `resume/` | the protocol's saved stages (state A, finished branches), for `--resume` |",
        "| `paraview/` | VTK snapshots of the labelled states (`--paraview`) |",
        "",
        "### history.nc and relaxed_states.nc",
        "",
        "Dimension `time` (unlimited): one record per output step (history) or relaxed state.",
        "",
        *_variable_table(HISTORY_VARIABLES),
        "",
        'Runs of bonded rods (`[particles] rod_model = "bonded"`) add:',
        "",
        *_variable_table(BONDED_HISTORY_VARIABLES),
        "",
        "The codes of `stage`:",
        "",
        "| code | stage |",
        "|---|---|",
        *[f"| {code} | `{label}` |" for label, code in STAGE_CODES.items()],
        "",
        "### probes.nc",
        "",
        "Dimensions `probe` (one per probed state), `amplitude` (the dynamic sweep's strain "
        "amplitudes), `voigt_i`, `voigt_j` (xx, yy, xy).",
        "",
        *_variable_table(PROBE_VARIABLES),
        "",
        "### configuration_&lt;label&gt;.nc",
        "",
        "Dimensions `rod`, `xy`.",
        "",
        *_variable_table(CONFIGURATION_VARIABLES),
        "",
        "## A sweep's members dataset",
        "",
        "`dem_taichi.sweep.results.open_sweep` (and the sweep's summary, "
        "`<table>_members.nc`): the findings of every finished member along `member`; every "
        "swept key is a coordinate along `member`.",
        "",
        "Per labelled state (dimensions `member`, `state`), with the attributes of the history "
        "or probe variable of the same name: "
        + ", ".join(f"`{k}`" for k in (*STATE_MEASURES, "e_oed_v", "e_oed_h", "e_ratio"))
        + " (`e_ratio` = E_oed,h / E_oed,v of the linear response).",
        "",
        'Per member (dimension `member`, `units = "1"`, DEM units where dimensional):',
        "",
        "| variable | meaning |",
        "|---|---|",
        *[f"| `{name}` | {_cell(long_name)} |" for name, _key, long_name in RUN_SCALARS],
        "",
        "## tiv_model element tests",
        "",
        "`python -m tiv_model isotropic|k0|unload|radial … --out FILE.nc` "
        "(`tiv_model.drivers.to_dataset`): dimension `step` (0 = the initial state); the "
        "model's parameters and options as global attributes `parameter_*`, `option_*`.",
        "",
        *_pairs_table(TIV_VARIABLES, "step"),
        "",
        "## bridge outputs",
        "",
        "The calibration's predictions, `prediction_<path>.nc` (`bridge.predict`), along `point` "
        "(the DEM's points of the path). Each variable has the attribute `role` (`input`, "
        "`fitted` or `out_of_sample`); where the DEM has the same variable, `dem_<name>` holds "
        "the DEM values and the attribute `error_rms` the RMS difference model − DEM.",
        "",
        *_pairs_table(prediction, "point"),
        "",
        "The model series made from DEM results (`bridge.series`), along `point`:",
        "",
        *_pairs_table(SERIES_VARIABLES, "point"),
        "",
    ]
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------
# Links of the exposed repository files
# ------------------------------------------------------------------------------------------

_LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)((?:\s+\"[^\"]*\")?)\)")


def _is_external(target: str) -> bool:
    return bool(re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target)) or target.startswith(("#", "/"))


def rewrite_repository_links(markdown: str, repo_file: Path, site_path: str) -> str:
    """Links of a repository file shown at ``site_path``, rewritten for the site (module
    docstring): to a docs page, to an exposed results file, or else plain code text."""
    site_dir = posixpath.dirname(site_path)

    def replace(match: re.Match) -> str:
        bang, text, target, title = match.groups()
        if _is_external(target):
            return match.group(0)
        path, _, anchor = target.partition("#")
        resolved = (repo_file.parent / path).resolve()
        try:
            rel = resolved.relative_to(ROOT).as_posix()
        except ValueError:
            return text if not bang else f"`{path}`"
        if rel.startswith("docs/"):
            new = rel[len("docs/") :]
        elif rel.startswith("benchmarks/results/"):
            new = f"{RESULTS_FILES}/{rel[len('benchmarks/results/') :]}"
        else:
            new = None
        if new is None or not (ROOT / rel).exists():
            return f"{text} (`{rel}`)" if text and not bang else f"`{rel}`"
        link = posixpath.relpath(new, site_dir or ".") + (f"#{anchor}" if anchor else "")
        return f"{bang}[{text}]({link}{title})"

    return _LINK.sub(replace, markdown)


def drop_missing_links(markdown: str, source: Path) -> str:
    """Links (and images) of an exposed results file to files that do not exist, as text."""

    def replace(match: re.Match) -> str:
        bang, text, target, _title = match.groups()
        if _is_external(target):
            return match.group(0)
        path = target.partition("#")[0]
        if not path or (source.parent / path).exists():
            return match.group(0)
        return f"{text} (`{path}`: not in the repository)"

    return _LINK.sub(replace, markdown)


# ------------------------------------------------------------------------------------------
# MkDocs events
# ------------------------------------------------------------------------------------------


def results_pages() -> list[str]:
    """Every ``docs/results/*.md`` as a docs path, ``results/index.md`` first."""
    pages = sorted(p.name for p in (DOCS / "results").glob("*.md"))
    if "index.md" in pages:
        pages.remove("index.md")
        pages.insert(0, "index.md")
    return [f"results/{name}" for name in pages]


def on_config(config, **kwargs):
    """Fill the nav entry "Results and validation" with every docs/results/*.md."""
    for entry in config["nav"] or []:
        if isinstance(entry, dict) and RESULTS_NAV_TITLE in entry:
            entry[RESULTS_NAV_TITLE] = results_pages() or entry[RESULTS_NAV_TITLE]
    return config


def on_files(files, config, **kwargs):
    """Add the generated references, the project files and the benchmarks' results files."""
    from mkdocs.structure.files import File

    def add(path: str, **source) -> None:
        if files.get_file_from_path(path) is None:
            files.append(File.generated(config, path, **source))

    add(SCENE_REFERENCE, content=scene_reference())
    add(RESULTS_REFERENCE, content=results_files_reference())
    for path, source in PROJECT_FILES.items():
        add(path, abs_src_path=str(source))
    if RESULTS.is_dir():
        for source in sorted(RESULTS.rglob("*")):
            if source.is_file() and not source.name.startswith("."):
                rel = source.relative_to(RESULTS).as_posix()
                add(f"{RESULTS_FILES}/{rel}", abs_src_path=str(source))
    return files


def on_page_markdown(markdown, page, config, files, **kwargs):
    """Rewrite the links of the exposed repository files (module docstring)."""
    path = page.file.src_uri
    if path in PROJECT_FILES:
        return rewrite_repository_links(markdown, PROJECT_FILES[path], path)
    if path.startswith(RESULTS_FILES + "/"):
        source = RESULTS / path[len(RESULTS_FILES) + 1 :]
        return drop_missing_links(markdown, source)
    return markdown
