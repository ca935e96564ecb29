"""Sphinx configuration of the documentation site (``make docs``: MyST Markdown, the furo theme, warnings as errors).

Generated before each build: ``reference/scene.md`` (the scene keys, from solver/config/reference.py) and
``demos/*.md`` (the demos/*.py jupytext scripts as MyST notebooks, text beside the code).
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))

import solver  # noqa: E402

project = "campo-solver"
author = "the campo-solver developers"
copyright = "2026, the campo-solver developers (LGPL-3.0-or-later)"
release = version = solver.__version__

extensions = ["myst_parser", "sphinx.ext.autodoc"]
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
html_theme = "furo"
html_title = f"campo-solver {release}"


def _generate(app) -> None:
    """Write the generated pages before Sphinx reads the sources."""
    import jupytext

    from solver.config.reference import markdown

    (DOCS / "reference").mkdir(exist_ok=True)
    page = DOCS / "reference" / "scene.md"
    if not page.exists() or page.read_text() != markdown():
        page.write_text(markdown())
    out = DOCS / "demos"
    out.mkdir(exist_ok=True)
    for script in sorted((ROOT / "demos").glob("*.py")):
        text = jupytext.writes(jupytext.read(script), fmt="md")
        target = out / (script.stem + ".md")
        if not target.exists() or target.read_text() != text:
            target.write_text(text)


def setup(app) -> None:
    app.connect("builder-inited", _generate)
