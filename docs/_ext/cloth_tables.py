"""Tables the site generates from the code, so they cannot drift from it.

* ``{cloth-parameters}`` — every parameter of :data:`cloth_sim.parameters.SCHEMA`: name, accepted
  values, unit, how a change applies, the scene-file key, the description.
* ``{cloth-integrators}`` — every registered integrator, in :data:`cloth_sim.kinds.INTEGRATORS`'
  order: order of accuracy, stability class, implicit or not, what it handles itself, the first
  line of its docstring.
* ``{cloth-scenes}`` — every scene in ``config/scenes/``: its first comment line, the cloth, the
  integrator and step.
* ``{cloth-materials}`` — every fabric of :mod:`cloth_sim.materials`' library: its values in SI
  units, its bending length and its source.
* ``{cloth-topics}``, ``{cloth-services}`` — the node's topics and services from
  :mod:`cloth_sim.ros.interface`, the declaration the node creates them from.
"""

from __future__ import annotations

from pathlib import Path

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util.docutils import SphinxDirective

ROOT = Path(__file__).resolve().parents[2]


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _list_table(header: list[str], rows: list[list[str]], widths: str = "auto") -> list[str]:
    lines = [".. list-table::", "   :header-rows: 1", f"   :widths: {widths}", ""]
    for row in [header, *rows]:
        lines.append(f"   * - {row[0]}")
        lines += [f"     - {c}" for c in row[1:]]
    return lines


class _Table(SphinxDirective):
    has_content = False

    def rows(self) -> tuple[list[str], list[list[str]]]:
        raise NotImplementedError

    def run(self):
        header, rows = self.rows()
        node = nodes.container()
        self.state.nested_parse(StringList(_list_table(header, rows)), self.content_offset, node)
        return node.children


class Parameters(_Table):
    def rows(self):
        from cloth_sim.parameters import SCHEMA

        out = []
        for name, p in SCHEMA.items():
            out.append(
                [
                    f"``{name}``",
                    _cell(p.range_text()),
                    _cell(p.unit or "—"),
                    p.apply,
                    f"``{p.scene_key}``" if p.scene_key else "—",
                    _cell(p.description),
                ]
            )
        return ["parameter", "accepted", "unit", "a change", "scene key", "what"], out


class Integrators(_Table):
    def rows(self):
        from cloth_sim import integrators

        out = []
        for name in integrators.available():
            cls = integrators.get(name)
            doc = (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
            handles = ", ".join(sorted(getattr(cls, "handles", ()) or ())) or "—"
            out.append(
                [
                    f"``{name}``",
                    str(cls.order),
                    cls.stability.name.lower().replace("_", " "),
                    "implicit" if cls.implicit else "explicit",
                    handles,
                    _cell(doc),
                ]
            )
        return ["name", "order", "stability", "kind", "handles itself", "what"], out


class Scenes(_Table):
    def rows(self):
        import yaml

        out = []
        for path in sorted((ROOT / "config" / "scenes").glob("*.yaml")):
            text = path.read_text()
            head = []
            for line in text.splitlines():
                if not line.startswith("#"):
                    break
                head.append(line[1:].strip())
            first = " ".join(head)
            data = yaml.safe_load(text)
            if "grid" in data:
                g = data["grid"]
                cloth = f"{g['rows']} × {g['cols']} grid"
            else:
                cloth = f"mesh ``{Path(data['mesh']['file']).name}``"
            if isinstance(data.get("material"), str):
                cloth += f", ``{data['material']}``"
            step = data.get("integrator", "symplectic_euler")
            dt = data.get("dt")
            out.append(
                [
                    f"``{path.stem}``",
                    cloth,
                    f"``{step}``" + (f" at {dt:g} s" if dt else ""),
                    _cell(first),
                ]
            )
        return ["scene", "cloth", "integrator", "what"], out


class Materials(_Table):
    def rows(self):
        from cloth_sim.materials import get, names
        from cloth_sim.materials.library import ALIASES, ARCSIM_DATA

        out = []
        for n in names():
            f = get(n)
            what = (
                f"the library's {ALIASES[n]}"
                if n in ALIASES
                else f"{ARCSIM_DATA[n][0]}, {ARCSIM_DATA[n][1]}"
            )
            out.append(
                [
                    f"``{n}``",
                    _cell(what),
                    f"{f.density:.3f}",
                    f"{f.stretch[0]:.4g} / {f.stretch[1]:.4g}",
                    f"{f.shear:.3g}",
                    f"{1e6 * f.bend[0]:.3g} / {1e6 * f.bend[1]:.3g}",
                    f"{f.poisson:.3f}",
                    f"{100 * f.bending_length(0):.2f} / {100 * f.bending_length(1):.2f}",
                ]
            )
        return [
            "fabric",
            "use, fibres",
            "density (kg/m²)",
            "stretch warp / weft (N/m)",
            "shear (N/m)",
            "bend warp / weft (µN·m)",
            "ν",
            "bending length (cm)",
        ], out


def _md(text: str) -> str:
    """The declaration's Markdown-ish backticks as reStructuredText literals."""
    return _cell(text).replace("`", "``")


class Topics(_Table):
    def rows(self):
        from cloth_sim.ros.interface import TOPICS

        out = []
        for t in TOPICS.values():
            qos = f"keep last {t.depth}" + (
                f", {t.durability}" if t.durability != "volatile" else ""
            )
            out.append(
                [
                    f"``{t.name.replace('{name}', '<name>')}``",
                    f"``{t.type}``",
                    "publishes" if t.direction == "out" else "subscribes",
                    qos,
                    _md(t.what),
                ]
            )
        return ["topic", "type", "the node", "QoS", "what"], out


class Services(_Table):
    def rows(self):
        from cloth_sim.ros.interface import SERVICES

        out = [[f"``{s.name}``", f"``{s.type}``", _md(s.what)] for s in SERVICES.values()]
        return ["service", "type", "what"], out


def setup(app):
    app.add_directive("cloth-parameters", Parameters)
    app.add_directive("cloth-integrators", Integrators)
    app.add_directive("cloth-scenes", Scenes)
    app.add_directive("cloth-materials", Materials)
    app.add_directive("cloth-topics", Topics)
    app.add_directive("cloth-services", Services)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
