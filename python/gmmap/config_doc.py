"""What each setting means, read from where its default is defined; the commented dump and the
reference page.

Each field of the sections (`gmmap.options`, `gmmap.fleet_options`, `gmmap.ros_options`,
`gmmap.sim_options`) carries its one-line meaning as a ``#:`` comment (the Sphinx convention for
attribute docs): beside the field, or on the line(s) right above it, where plain ``#`` comments may
explain why the default is what it is. ``gmmap config --dump`` writes each meaning as a YAML comment
above its key (the file loads back unchanged), and ``gmmap config --reference`` writes the Markdown
reference, ``docs/guide/config-reference.md``. Reading the comments needs the modules' source, which
an installed package has beside its bytecode.
"""

from __future__ import annotations

import ast
import functools
import inspect
import io
import textwrap
import tokenize
from dataclasses import fields
from typing import Any

import yaml

from gmmap.config import Config, _plain

MAX_MEANING = 90  # characters of one setting's meaning
REFERENCE_PATH = "docs/guide/config-reference.md"
REGENERATE = f"gmmap config --reference > {REFERENCE_PATH}"


@functools.cache
def meanings(cls: type) -> dict[str, str]:
    """``{field: meaning}`` of a section's dataclass, from its ``#:`` comments: the one
    beside the field, else those of the comment block right above it (joined)."""
    source = textwrap.dedent(inspect.getsource(cls))
    marked: dict[int, str] = {}  # line -> text of a `#:` comment
    beside: set[int] = set()  # lines where that comment follows code
    full_line: set[int] = set()  # lines that hold only a comment
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type != tokenize.COMMENT:
            continue
        row, col = tok.start
        if tok.line[:col].strip():
            beside.add(row)
        else:
            full_line.add(row)
        if tok.string.startswith("#:"):
            marked[row] = tok.string[2:].strip()
    names = {f.name for f in fields(cls)}
    found = {}
    for node in ast.parse(source).body[0].body:  # type: ignore[attr-defined]
        if not (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name)):
            continue
        if node.target.id not in names:
            continue
        rows = range(node.lineno, (node.end_lineno or node.lineno) + 1)
        text = [marked[r] for r in rows if r in marked and r in beside]
        if not text:
            row = node.lineno - 1
            while row in full_line:
                if row in marked:
                    text.insert(0, marked[row])
                row -= 1
        if text:
            found[node.target.id] = " ".join(text)
    return found


def sections() -> dict[str, type]:
    """``{section: its dataclass}`` in the tree's order."""
    return {f.name: type(f.default_factory()) for f in fields(Config)}  # type: ignore[misc]


def summary(cls: type) -> str:
    """A section's one-line summary: the first sentence of its dataclass's docstring, or of
    a long one what comes before its first colon."""
    first = inspect.cleandoc(cls.__doc__ or "").split("\n\n")[0]
    text = " ".join(first.split())
    end = text.find(". ")
    text = text if end < 0 else text[: end + 1]
    if len(text) > MAX_MEANING + 10 and ": " in text:
        text = text[: text.index(": ")] + "."
    return text


def missing() -> list[str]:
    """``section.key`` of every setting without a meaning: what a new setting must add."""
    return [
        f"{name}.{f.name}"
        for name, cls in sections().items()
        for f in fields(cls)
        if f.name not in meanings(cls)
    ]


def commented_dump(config: Config | None = None) -> str:
    """``config.dump()`` (the defaults where None) with a YAML comment above each section and
    each key saying what it is: the same values, the same lines, comments added."""
    config = config or Config()
    out = [
        "# gmmap configuration: every setting, its meaning above it.",
        "# Keep what you change (what a file leaves out keeps its default) and give the file",
        "# to any command with --config FILE; its flags override single keys.",
    ]
    for name, cls in sections().items():
        out += ["", f"# {summary(cls)}"]
        out.append(f"{name}:")
        values = _plain(getattr(config, name))
        meaning = meanings(cls)
        for key, value in values.items():
            if key in meaning:
                out.append(f"  # {meaning[key]}")
            text = yaml.safe_dump({key: value}, sort_keys=False, default_flow_style=False)
            out.extend("  " + line for line in text.splitlines())
    return "\n".join(out) + "\n"


def _inline(value: Any) -> str:
    """A default as one line of YAML (flow style)."""
    text = yaml.safe_dump(_plain(value), default_flow_style=True, width=1 << 16).strip()
    return text.removesuffix("...").strip()


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def reference() -> str:
    """The configuration reference in Markdown: per section its docstring, then a table of
    every key, its default and its meaning."""
    out = [
        "# Configuration reference",
        "",
        "<!-- Generated from the code: do not edit; regenerate with the command below. -->",
        "",
        "Every setting of the configuration tree ([Configuration](configuration.md)), with its",
        "default and what it means. This page is generated from the `#:` comments beside the",
        "defaults in `python/gmmap/options.py`, `python/gmmap/fleet_options.py`,",
        "`python/gmmap/ros_options.py` and `python/gmmap/sim_options.py` (the same text as the",
        "comments of `gmmap config --dump`)",
        "and the sections' docstrings there.",
        "Regenerate it after changing a setting (a test fails while it is out of date):",
        "",
        "```sh",
        REGENERATE,
        "```",
        "",
        "Sections: " + ", ".join(f"[`{name}`](#{name})" for name in sections()) + ".",
    ]
    defaults = Config()
    for name, cls in sections().items():
        meaning = meanings(cls)
        out += ["", f"## {name}", "", inspect.cleandoc(cls.__doc__ or ""), ""]
        out += ["| key | default | meaning |", "|---|---|---|"]
        for f in fields(cls):
            value = _inline(getattr(getattr(defaults, name), f.name))
            text = _cell(meaning.get(f.name, ""))
            out.append(f"| `{name}.{f.name}` | `{_cell(value)}` | {text} |")
    return "\n".join(out) + "\n"
