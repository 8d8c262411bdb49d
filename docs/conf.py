"""Sphinx configuration of the bboxtune documentation: Markdown pages (MyST), the Furo theme, API pages from the
docstrings (autodoc), as Gymnasium and stable-baselines3 do.

    python -m sphinx -W --keep-going -b html docs docs/_build/html

(``-W``: every warning is an error; ``tests/test_docs.py`` runs the same build.)
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from docutils import nodes
from sphinx import addnodes
from sphinx.transforms import SphinxTransform

import bboxtune

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent

project = "bboxtune"
author = "the bboxtune contributors"
copyright = "2026, the bboxtune contributors"
release = bboxtune.__version__
version = release

extensions = ["myst_parser", "sphinx.ext.autodoc"]  # docstrings are reST (env classes: see below), no napoleon
source_suffix = {".md": "markdown"}
root_doc = "index"
# Pages are the .md files of docs/ except:
# * _build: the output;
# * results/: what scripts/compare.py and the other commands wrote (summary.md, results.csv, plots, runs). These
#   generated folders are not edited for the site (some summaries name plots that were not committed), so they are
#   not pages; a page links into them as described at LocalFileLinks below.
exclude_patterns = ["_build", "results"]

myst_heading_anchors = 3  # links to a page's headings: [text](results-otb.md#a-learned-gate)
myst_enable_extensions: list[str] = []

autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": False}
autodoc_typehints = "description"
autodoc_inherit_docstrings = False  # Gymnasium's own Env.step / reset docstrings are Google-style, not ours

html_theme = "furo"
html_title = f"bboxtune {release}"
html_static_path: list[str] = []


# --- Links from a page to files and folders of the repository (docs/results/..., agents/...) --------------------
#
# The pages keep the README's relative links, so the same Markdown works on GitHub and on the site. MyST resolves a
# link to an existing file that is not a page (a .png, .csv, .txt under results/) as a *download*: the file is copied
# into the site's _downloads/ and the link points there, and a link to a missing file is a warning, so
# `sphinx-build -W` catches it. Two kinds of link need help, and LocalFileLinks gives it while a page is read (before
# Sphinx collects the downloads):
# * a .md file that is not a page (a generated summary.md under results/, agents/pretrained/<name>/summary.md):
#   MyST takes every .md link for a page and would warn "Unknown source document"; it becomes a download like any
#   other file;
# * a folder (docs/results/otb_kf_cmn, a run directory): MyST would warn that the target is not found. A folder with
#   a summary.md links to that summary (a download); any other folder is shown as its path from the repository
#   root, as code, without a link.
# A link whose target exists neither as a file nor as a folder is left to MyST, which reports it.
# Code files are named in the pages as plain code spans (`agents/gate.py`), not linked.

def _repo_path(path: Path) -> str:
    try:
        return path.resolve().relative_to(ROOT).as_posix()
    except ValueError:
        return path.as_posix()


class LocalFileLinks(SphinxTransform):
    """Links to repository files that are not pages, and to folders (see above)."""

    default_priority = 500  # while reading, after MyST has made its pending references

    def _download(self, node: addnodes.pending_xref, path: Path, here: Path) -> None:
        link = addnodes.download_reference(refdomain=None, reftype="myst", refexplicit=True, refdoc=self.env.docname,
                                           reftarget=os.path.relpath(path, here))
        link += nodes.inline("", "", *[child.deepcopy() for child in node.children], classes=["xref", "download", "myst"])
        node.replace_self(link)

    def apply(self, **kwargs: object) -> None:
        here = Path(self.env.doc2path(self.env.docname)).parent
        for node in list(self.document.findall(addnodes.pending_xref)):
            if node.get("reftype") != "myst":
                continue
            if node.get("refdomain") == "doc":  # a .md link: a page, or a Markdown file that is not one
                docname = str(node["reftarget"])
                source = Path(self.env.doc2path(docname))
                if docname not in self.env.found_docs and source.is_file():
                    self._download(node, source, here)
                continue
            if node.get("refdomain"):
                continue
            target = str(node["reftarget"]).split("#", 1)[0]
            if not target or "://" in target:
                continue
            folder = (here / target).resolve()
            if not folder.is_dir():
                continue
            if (folder / "summary.md").is_file():
                self._download(node, folder / "summary.md", here)
            else:
                text = node.astext().strip().rstrip("/")
                path = _repo_path(folder) + "/"
                if text and path.rstrip("/").endswith(text):
                    node.replace_self(nodes.literal(path, path))
                else:
                    node.replace_self([*[child.deepcopy() for child in node.children], nodes.Text(" ("),
                                       nodes.literal(path, path), nodes.Text(")")])


# --- Gymnasium-style env docstrings -----------------------------------------------------------------------------
#
# The env classes document themselves as Gymnasium's do: Markdown sections (``## Action Space``) and Markdown
# tables inside an otherwise reST docstring (double-backtick code, :mod: roles, doctest blocks). autodoc parses
# docstrings as reST, so for a docstring with such sections the headings become rubrics, the tables list-tables,
# and a bare "|" in the text (|x − y|) is escaped; every other docstring is passed through unchanged.

_HEADING = re.compile(r"^(\s*)#{2,4} (\S.*)$")
_TABLE_RULE = re.compile(r"^\s*\|[\s:|-]+\|\s*$")
_LITERAL = re.compile(r"(``.*?``)")


def _cells(line: str) -> list[str]:
    return [cell.strip() for cell in line.strip().strip("|").split("|")]


def _escape_bars(line: str) -> str:
    return "".join(part if part.startswith("``") else part.replace("|", r"\|") for part in _LITERAL.split(line))


def markdown_sections_to_rest(lines: list[str]) -> list[str]:
    """The docstring ``lines`` with Markdown headings and tables rewritten as reST (see above)."""
    out: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        heading = _HEADING.match(line)
        if heading:
            indent = heading.group(1)
            out += ["", f"{indent}.. rubric:: {heading.group(2).strip()}", ""]
            i += 1
            continue
        if line.lstrip().startswith("|") and i + 1 < len(lines) and _TABLE_RULE.match(lines[i + 1]):
            indent = line[: len(line) - len(line.lstrip())]
            rows = [_cells(line)]
            i += 2
            while i < len(lines) and lines[i].lstrip().startswith("|"):
                rows.append(_cells(lines[i]))
                i += 1
            out += ["", f"{indent}.. list-table::", f"{indent}   :header-rows: 1", ""]
            for row in rows:
                for k, cell in enumerate(row):
                    bullet = "* -" if k == 0 else "  -"
                    out.append(f"{indent}   {bullet} {cell}".rstrip())
            out.append("")
            continue
        out.append(_escape_bars(line))
        i += 1
    return out


def _gymnasium_docstring(app: object, what: str, name: str, obj: object, options: object, lines: list[str]) -> None:
    if any(_HEADING.match(line) for line in lines):
        lines[:] = markdown_sections_to_rest(lines)


def setup(app: object) -> dict[str, bool]:
    app.add_transform(LocalFileLinks)
    app.connect("autodoc-process-docstring", _gymnasium_docstring)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
