"""The site and the README (make docs builds the site with warnings as errors, in CI): the tables
the site generates hold every parameter, integrator and scene the code has; the README is short and
its local links resolve; no page carries Python that no test runs (the pages include examples/)."""

import importlib.util
import re
from pathlib import Path

import pytest

pytest.importorskip("sphinx")

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"


def tables():
    spec = importlib.util.spec_from_file_location(
        "cloth_tables", DOCS / "_ext" / "cloth_tables.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def rows(cls):
    return cls.__new__(cls).rows()[1]


def test_the_generated_tables_hold_everything_the_code_has():
    from cloth_sim import integrators
    from cloth_sim.parameters import SCHEMA

    t = tables()
    params = rows(t.Parameters)
    assert [r[0] for r in params] == [f"``{name}``" for name in SCHEMA]
    dt = next(r for r in params if r[0] == "``dt``")
    assert dt[1] == "a number in [1e-07, 1] s" and dt[3] == "live"
    names = [r[0] for r in rows(t.Integrators)]
    assert names == [f"``{n}``" for n in integrators.available()] and len(names) == 11
    scenes = {r[0] for r in rows(t.Scenes)}
    assert scenes == {f"``{p.stem}``" for p in (ROOT / "config" / "scenes").glob("*.yaml")}


def local_links(text: str):
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if "://" not in target and not target.startswith(("#", "mailto:")):
            yield target.split("#")[0]


def test_the_readme_is_short_and_its_local_links_resolve():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 150
    missing = [t for t in local_links(text) if t and not (ROOT / t).exists()]
    assert missing == []


def test_no_page_carries_python_that_no_test_runs():
    """Python in the pages comes from examples/ (literalinclude), which test_examples.py runs."""
    for page in DOCS.glob("*.md"):
        assert "```python" not in page.read_text(), page.name
    included = set()
    for page in DOCS.glob("*.md"):
        included |= set(re.findall(r"literalinclude\}\s+\.\./(examples/\S+)", page.read_text()))
    assert included and all((ROOT / f).exists() for f in included)


def test_the_sweep_specs_the_docs_show_are_valid():
    from cloth_sim.sweep import load_spec

    specs = sorted((DOCS / "sweeps").glob("*.yaml"))
    assert len(specs) >= 3
    for path in specs:
        assert len(load_spec(path)) > 0, path
