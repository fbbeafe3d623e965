"""The documentation site (issue 21): it builds with warnings as errors, its generated references
are complete, its code examples run, and the docstrings' citations of docs pages resolve.

- ``mkdocs build --strict`` (``make docs``) into a temporary folder must succeed: a broken link,
  a missing page or a docstring mkdocstrings cannot render fails ``make test`` here.
- The scene reference (``docs/hooks.py``: ``scene_reference``) lists every key of every scene
  section with its default, and every key carries a description and a unit in its metadata.
- The results-files reference lists every variable of the schema tables with its units.
- Every fenced ``python`` block of ``docs/**/*.md`` and ``README.md`` runs (README.md's with
  ``make test-slow``: it runs a whole protocol): the blocks of one
  page in order, in one fresh process, in an empty temporary folder (blocks fenced as ``pycon``,
  ``text``, ``console``, ``bash`` or ``toml`` are not run).
- Every ``docs/<page>.md`` cited in a docstring of ``dem_taichi``, ``tiv_model`` or ``bridge``
  exists, and a ``§X.Y`` after it names a heading of that page.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import os
import re
import subprocess
import sys
import textwrap
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PACKAGES = ("dem_taichi", "tiv_model", "bridge")
#: every folder of Python whose docstrings may cite the docs (this file names the outside
#: documents on purpose, in the pattern that refuses them)
SOURCES = (*PACKAGES, "tests", "benchmarks", "scripts")
#: seconds one page's examples may take (the DEM examples compile Taichi kernels first)
EXAMPLE_TIMEOUT = 300


def _load_hooks():
    spec = importlib.util.spec_from_file_location("docs_hooks", DOCS / "hooks.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


hooks = _load_hooks()


def _quiet_env() -> dict[str, str]:
    env = dict(os.environ)
    env["NO_MKDOCS_2_WARNING"] = "1"  # Material's banner about MkDocs 2 (not a warning of ours)
    env["MPLBACKEND"] = "Agg"
    env.setdefault("TI_LOG_LEVEL", "warn")
    return env


# ------------------------------------------------------------------------------------------
# The build
# ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def built_site(tmp_path_factory):
    """The site built once by ``mkdocs build --strict``: (return code, output, site folder)."""
    for package in ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python"):
        pytest.importorskip(
            package, reason="the docs extra is not installed (pip install -e .[docs])"
        )
    site = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=_quiet_env(),
        timeout=600,
    )
    return proc.returncode, proc.stdout + proc.stderr, site


def test_site_builds_with_warnings_as_errors(built_site):
    rc, output, site = built_site
    problems = [line for line in output.splitlines() if line.startswith(("WARNING", "ERROR"))]
    assert rc == 0, "mkdocs build --strict failed:\n" + "\n".join(problems or [output[-3000:]])
    assert (site / "index.html").exists()


def test_site_has_the_generated_and_exposed_pages(built_site):
    rc, _output, site = built_site
    if rc != 0:
        pytest.skip("the build failed (test_site_builds_with_warnings_as_errors)")
    for page in (
        "reference/scene",
        "reference/results-files",
        "reference/api/dem_taichi",
        "reference/api/tiv_model",
        "reference/api/bridge",
        "reference/api/clay_cli",
        "project/architecture",
        "project/changelog",
    ):
        assert (site / page / "index.html").exists(), page
    scene = (site / "reference" / "scene" / "index.html").read_text(encoding="utf-8")
    for name, cls in hooks.scene_sections().items():
        assert f'id="{name}"' in scene, f"[{name}] has no heading in the scene reference"
        for f in dataclasses.fields(cls):
            assert f"<code>{f.name}</code>" in scene, f"[{name}] {f.name}"
    results = hooks.RESULTS
    for source in results.glob("*"):
        if source.is_file():
            target = "results/files/" + (
                source.stem + "/index.html" if source.suffix == ".md" else source.name
            )
            assert (site / target).exists(), f"{source} is not in the site at {target}"


def test_site_has_no_duplicate_anchors(built_site):
    """An object documented twice (a top-level name and its module) gives two equal ids."""
    rc, _output, site = built_site
    if rc != 0:
        pytest.skip("the build failed (test_site_builds_with_warnings_as_errors)")
    duplicated = {}
    for page in sorted(site.rglob("index.html")):
        ids = Counter(re.findall(r' id="([^"]+)"', page.read_text(encoding="utf-8")))
        twice = sorted(i for i, n in ids.items() if n > 1)
        if twice:
            duplicated[page.relative_to(site).as_posix()] = twice[:5]
    assert not duplicated, f"ids used twice on a page: {duplicated}"


def _nav_pages(nav) -> list[str]:
    pages = []
    for entry in nav:
        value = next(iter(entry.values())) if isinstance(entry, dict) else entry
        pages += _nav_pages(value) if isinstance(value, list) else [value]
    return pages


def test_every_page_is_in_the_nav():
    """Every page under docs/ is reachable from the nav (the build only notes omitted pages,
    because the exposed benchmarks/results files are pages outside the nav); every
    docs/results/*.md is listed without an edit of mkdocs.yml."""
    pytest.importorskip("mkdocs", reason="the docs extra is not installed (.[docs])")
    import yaml

    config = yaml.safe_load(
        "\n".join(
            line
            for line in (ROOT / "mkdocs.yml").read_text("utf-8").splitlines()
            if "!!python" not in line
        )
    )
    hooks.on_config(config)
    nav = set(_nav_pages(config["nav"]))
    pages = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    assert pages - nav == set(), "pages under docs/ that the nav does not list"
    generated = {hooks.SCENE_REFERENCE, hooks.RESULTS_REFERENCE, *hooks.PROJECT_FILES}
    assert nav - pages - generated == set(), "nav entries without a page"
    assert [p for p in _nav_pages(config["nav"]) if p.startswith("results/")] == [
        "results/index.md",
        *sorted(p for p in pages if p.startswith("results/") and p != "results/index.md"),
    ]


def test_links_of_the_exposed_repository_files():
    text = (
        "[guide](docs/guide/engine.md#rigid-or-bonded-rods) "
        "[bench](benchmarks/results/speed_accuracy.md) "
        "![figure](benchmarks/results/speed_accuracy.png) "
        "[code](dem_taichi/scene/config.py) [web](https://example.org/x.md) [here](#section)"
    )
    out = hooks.rewrite_repository_links(text, ROOT / "ARCHITECTURE.md", "project/architecture.md")
    assert "[guide](../guide/engine.md#rigid-or-bonded-rods)" in out
    assert "[bench](../results/files/speed_accuracy.md)" in out
    assert "![figure](../results/files/speed_accuracy.png)" in out
    assert (
        "code (`dem_taichi/scene/config.py`)" in out and "(dem_taichi/scene/config.py)" not in out
    )
    assert "[web](https://example.org/x.md)" in out and "[here](#section)" in out
    missing = "![plot](no_such_figure.png) [table](speed_accuracy.csv)"
    out = hooks.drop_missing_links(missing, hooks.RESULTS / "report.md")
    assert "![plot]" not in out and "[table](speed_accuracy.csv)" in out


# ------------------------------------------------------------------------------------------
# The scene reference
# ------------------------------------------------------------------------------------------


def _section_tables(markdown: str) -> dict[str, dict[str, list[str]]]:
    """``## [section]`` -> key -> the cells of its table row."""
    tables: dict[str, dict[str, list[str]]] = {}
    current = None
    for line in markdown.splitlines():
        heading = re.match(r"^## \[(\w+)\]\s*$", line)
        if heading:
            current = tables.setdefault(heading.group(1), {})
            continue
        if line.startswith("## "):
            current = None
        if current is not None and line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
            current[cells[0].strip("`")] = cells
    return tables


def _expected_default(f: dataclasses.Field) -> str:
    value = f.default
    if value is None:
        return "unset"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return '"' + value.replace('"', '\\"') + '"'
    return repr(value)


def test_scene_reference_lists_every_key_with_its_default():
    from dem_taichi.scene import config

    sections = {**config._CORE_SECTIONS, **config._EXTENSION_SECTIONS}
    assert set(hooks.scene_sections()) == set(sections)
    assert {"scene", "particles", "contact", "protocol", "probing"} <= set(sections)
    tables = _section_tables(hooks.scene_reference())
    assert set(tables) == set(sections), "sections of the reference != the scene's sections"
    for name, cls in sections.items():
        fields = {f.name: f for f in dataclasses.fields(cls)}
        assert set(tables[name]) == set(fields), f"[{name}]: keys differ"
        for key, f in fields.items():
            cells = tables[name][key]
            assert len(cells) == 6, f"[{name}] {key}: {cells}"
            assert cells[2].strip("`") == _expected_default(f), f"[{name}] {key}: default"
            assert cells[4] == f.metadata["unit"], f"[{name}] {key}: unit"


def test_every_scene_key_has_a_description_and_a_unit():
    missing = []
    for name, cls in hooks.scene_sections().items():
        for f in dataclasses.fields(cls):
            doc, unit = f.metadata.get("doc", ""), f.metadata.get("unit", "")
            if not doc.strip() or not unit.strip():
                missing.append(f"[{name}] {f.name} (doc {doc!r}, unit {unit!r})")
            elif "\n" in doc:
                missing.append(f"[{name}] {f.name}: the doc is not one line")
    assert not missing, "keys without a description or unit:\n" + "\n".join(missing)


def test_scene_reference_states_ranges_and_choices():
    from dem_taichi.scene.sections import Contact, Integration

    rows = {row["key"]: row for row in hooks.scene_rows(Contact)}
    assert rows["e_n"]["allowed"] == "(0.0, 1.0]"
    assert rows["e_n"]["default"] == "unset" and "optional" in rows["e_n"]["type"]
    assert rows["restitution_model"]["allowed"] == '`"discrete"` | `"continuous"`'
    rows = {row["key"]: row for row in hooks.scene_rows(Integration)}
    assert rows["dt_safety"]["allowed"] == "[0.001, 0.5]"
    assert rows["local_damping"]["allowed"] == "[0.0, 1.0)"


# ------------------------------------------------------------------------------------------
# The results-files reference
# ------------------------------------------------------------------------------------------


def test_results_reference_lists_every_variable():
    from dem_taichi.io.history_schema import BONDED_HISTORY_VARIABLES
    from dem_taichi.io.schema import CONFIGURATION_VARIABLES, HISTORY_VARIABLES, PROBE_VARIABLES
    from tiv_model.drivers import VARIABLES

    text = hooks.results_files_reference()
    rows: dict[str, list[list[str]]] = {}
    for line in text.splitlines():
        if line.startswith("| `"):
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
            rows.setdefault(cells[0].strip("`"), []).append(cells)
    for v in (
        *HISTORY_VARIABLES,
        *BONDED_HISTORY_VARIABLES,
        *PROBE_VARIABLES,
        *CONFIGURATION_VARIABLES,
    ):
        assert v.name in rows, v.name
        assert any(f"`{v.units}`" in cells and ", ".join(v.dims) in cells for cells in rows[v.name])
    for name, (units, _long_name) in VARIABLES.items():
        assert name in rows and any(f"`{units}`" in cells for cells in rows[name]), name


def test_results_reference_lists_every_file_of_a_run_directory():
    from dem_taichi.io.run_manifest import RUN_FILE_PATTERNS

    text = hooks.results_files_reference()
    for pattern in RUN_FILE_PATTERNS:
        assert re.search(rf"`{re.escape(pattern)}/?`", text), pattern


# ------------------------------------------------------------------------------------------
# Code examples
# ------------------------------------------------------------------------------------------

_FENCE = re.compile(r"^(?P<indent>[ \t]*)(?P<fence>`{3,}|~{3,})\s*(?P<info>[^`\n]*)$")
#: fenced-block languages that are run; every other one (pycon, text, console, bash, toml…) is not
RUN_LANGUAGES = {"python", "py", "python3"}


def fenced_blocks(text: str) -> list[tuple[str, int, str]]:
    """(language, first line number, code) of every fenced block of a Markdown text."""
    blocks = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        match = _FENCE.match(lines[i])
        if not match:
            i += 1
            continue
        fence, info = match.group("fence"), match.group("info").strip()
        language = re.split(r"[\s{]", info.lstrip("{").lstrip("."), maxsplit=1)[0].lower()
        start, body = i + 1, []
        i += 1
        while i < len(lines):
            closing = _FENCE.match(lines[i])
            if closing and closing.group("fence").startswith(fence) and not closing.group("info"):
                break
            body.append(lines[i])
            i += 1
        blocks.append((language, start, textwrap.dedent("\n".join(body))))
        i += 1
    return blocks


def _example_pages() -> list[Path]:
    pages = sorted(DOCS.rglob("*.md")) + [ROOT / "README.md"]
    return [
        p
        for p in pages
        if p.exists()
        and any(lang in RUN_LANGUAGES for lang, _, _ in fenced_blocks(p.read_text("utf-8")))
    ]


def test_fenced_blocks_are_found():
    text = 'a\n```python\nx = 1\n```\n\n    ```py title="t"\n    y = 2\n    ```\n'
    text += "```toml\n[a]\n```\n~~~~ pycon\n>>> 1\n~~~~\n"
    assert fenced_blocks(text) == [
        ("python", 2, "x = 1"),
        ("py", 6, "y = 2"),
        ("toml", 9, "[a]"),
        ("pycon", 12, ">>> 1"),
    ]


#: pages whose examples take minutes, run by ``make test-slow`` only: page -> why
SLOW_EXAMPLE_PAGES: dict[str, str] = {}


def _example_params() -> list:
    params = []
    for page in _example_pages():
        name = page.relative_to(ROOT).as_posix()
        marks = [pytest.mark.slow] if name in SLOW_EXAMPLE_PAGES else []
        params.append(pytest.param(page, id=name, marks=marks))
    return params


@pytest.mark.parametrize("page", _example_params())
def test_code_examples_run(page, tmp_path):
    blocks = [
        (line, code)
        for lang, line, code in fenced_blocks(page.read_text("utf-8"))
        if lang in RUN_LANGUAGES
    ]
    name = page.relative_to(ROOT).as_posix()
    script = []
    for line, code in blocks:
        script.append(f"# --- {name}, line {line}")
        script.append(f"print('--- example of {name}, line {line}', flush=True)")
        script.append(code)
    path = tmp_path / "examples.py"
    path.write_text("\n".join(script) + "\n", encoding="utf-8")
    proc = subprocess.run(
        [sys.executable, str(path)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=_quiet_env(),
        timeout=EXAMPLE_TIMEOUT,
    )
    marks = re.findall(r"--- example of .*", proc.stdout)
    where = marks[-1] if marks else "before the first example"
    assert proc.returncode == 0, (
        f"{name}: the example at {where.removeprefix('--- example of ')} failed:\n"
        f"{proc.stderr[-3000:]}"
    )


# ------------------------------------------------------------------------------------------
# Citations of docs pages in docstrings
# ------------------------------------------------------------------------------------------

_CITATION = re.compile(
    r"\bdocs/(?P<page>[\w./-]+?\.md)(?:[\s,;:(]*§+\s*(?P<section>\d+(?:\.\d+)*[a-z]?))?"
)


def _source_files() -> list[Path]:
    """The .py files of :data:`SOURCES`."""
    return [path for folder in SOURCES for path in sorted((ROOT / folder).rglob("*.py"))]


def docstring_citations() -> list[tuple[str, int, str, str | None]]:
    """(file, line, page, section or None) of every ``docs/<page>.md`` cited in the sources."""
    found = []
    for path in _source_files():
        text = path.read_text("utf-8")
        for match in _CITATION.finditer(text):
            line = text.count("\n", 0, match.start()) + 1
            rel = path.relative_to(ROOT).as_posix()
            found.append((rel, line, match.group("page"), match.group("section")))
    return found


def _has_section(page: Path, section: str) -> bool:
    heading = re.compile(rf"^#+\s+{re.escape(section)}(?![\w.])", re.MULTILINE)
    return bool(heading.search(page.read_text("utf-8")))


def test_docstring_citations_resolve():
    generated = {hooks.SCENE_REFERENCE, hooks.RESULTS_REFERENCE, *hooks.PROJECT_FILES}
    bad = []
    for rel, line, page, section in docstring_citations():
        target = DOCS / page
        if page in generated:
            continue
        if not target.is_file():
            bad.append(f"{rel}:{line}: docs/{page} does not exist")
        elif section and not _has_section(target, section):
            bad.append(f"{rel}:{line}: docs/{page} has no heading §{section}")
    assert not bad, "citations of docs pages that do not resolve:\n" + "\n".join(bad)


def test_no_citation_of_documents_outside_the_repository():
    outside = re.compile(r"(?<![\w/-])(?:model\.md|notes/dem_interfaces\.md|shared/design/)")
    bad = []
    for path in _source_files():
        if path.resolve() != Path(__file__).resolve():
            for number, line in enumerate(path.read_text("utf-8").splitlines(), 1):
                if outside.search(line):
                    bad.append(f"{path.relative_to(ROOT).as_posix()}:{number}: {line.strip()}")
    assert not bad, "citations of documents outside the repository:\n" + "\n".join(bad)
