"""A griffe extension (``mkdocs.yml``: the python handler's ``extensions``) that renders the
reST habits of the project's docstrings as Markdown, at build time only (the source is not
changed):

- Sphinx roles, ``:class:`~pkg.Name```, ``:func:`f```, … → the code span `pkg.Name`;
- doctest blocks (lines from ``>>>`` to the next blank line) → a fenced ``pycon`` block
  (Markdown would read the ``>>>`` as nested quotes);
- a paragraph ending in ``::`` before an indented literal block → a single ``:`` (the block
  itself is already an indented code block in Markdown).
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(
    r":(?:py:)?(?:mod|class|func|meth|attr|data|exc|obj|const|ref|term|doc|cite):`~?\.?([^`]+)`"
)
_LITERAL = re.compile(r"(?<=\S)::(\n\s*\n[ \t]+\S)")


def _doctest_blocks(text: str) -> str:
    out: list[str] = []
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith(">>>"):
            indent = line[: len(line) - len(line.lstrip())]
            block = []
            while i < len(lines) and lines[i].strip():
                block.append(lines[i][len(indent) :] if lines[i].startswith(indent) else lines[i])
                i += 1
            out += [f"{indent}```pycon", *(indent + b for b in block), f"{indent}```"]
            continue
        out.append(line)
        i += 1
    return "\n".join(out)


def rest_to_markdown(text: str) -> str:
    """The docstring ``text`` with the reST habits above rendered as Markdown."""
    text = _ROLE.sub(r"`\1`", text)
    text = _LITERAL.sub(r":\1", text)
    if ">>>" in text:
        text = _doctest_blocks(text)
    return text


class RestToMarkdown(griffe.Extension):
    """Rewrite every docstring with :func:`rest_to_markdown` as griffe loads it."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rest_to_markdown(obj.docstring.value)
