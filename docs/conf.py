"""The cloth_sim site: Sphinx with MyST (the pages are Markdown), autodoc from the docstrings, and
tables generated from the code (docs/_ext/cloth_tables.py).

    make docs    # build/docs/html, warnings as errors

rosdoc2 builds it too (rosdoc2.yaml at the package's root: sphinx_sourcedir docs).
"""

import re
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(HERE / "_ext"))

project = "cloth_sim"
author = "the cloth_sim developers"
copyright = "2026, the cloth_sim developers"
release = re.search(r"<version>(.+?)</version>", (ROOT / "package.xml").read_text()).group(1)
version = release

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",  # the docstrings' "Parameters:" sections (Google style)
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinxcontrib.mermaid",
    "cloth_tables",
]
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
myst_heading_anchors = 3
myst_fence_as_directive = ["mermaid"]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["bench/**/*.csv", "bench/**/*.json", "_build", "envs/*.py", "*.py"]
suppress_warnings = ["myst.header"]  # pages moved from the README start below h1 in places

autodoc_member_order = "bysource"
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_typehints = "description"
autodoc_inherit_docstrings = False  # Gymnasium's own docstrings are not ours to render

html_theme = "furo"
html_title = f"cloth_sim {release}"
