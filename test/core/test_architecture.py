"""The house rules the layout keeps (README "Layout"), read from the source with ``ast``: no import
circles among cloth_sim's modules (lazy imports inside functions included), no module taking
another's private name, and the core importing no ROS."""

import ast
import sys
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "cloth_sim"
#: the adapters, the command line and the measurement code: outside the core
EDGE = (
    "cloth_sim.ros",
    "cloth_sim.bag",
    "cloth_sim.sweep",
    "cloth_sim.envs",
    "cloth_sim.dataset",
    "cloth_sim.bench",
    "cloth_sim.cli",  # the command line: a front end over the core and the adapters
    "cloth_sim.textile",  # the textile standard tests, run on the simulator
    "cloth_sim.fit",  # a scene's material fitted to a recording
)
ROS = ("rclpy", "rcl_interfaces", "std_msgs", "sensor_msgs", "geometry_msgs", "rosgraph_msgs")


def modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def imports(name: str, is_package: bool, source: str, known) -> list[tuple[str, str | None]]:
    """``(module imported, name taken from it or None)`` for every import in module ``name``'s
    ``source`` (``known``: the package's module names)."""
    package = name if is_package else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            for a in node.names:
                sub = f"{target}.{a.name}"
                found.append((sub, None) if sub in known else (target, a.name))
    return found


def graph() -> tuple[dict, list]:
    known = modules()
    edges, private = {m: set() for m in known}, []
    for name, path in known.items():
        for target, taken in imports(name, path.name == "__init__.py", path.read_text(), known):
            while target and target not in known:
                target = target.rpartition(".")[0]
            if target and target != name:
                edges[name].add(target)
                if taken and taken.startswith("_") and not taken.startswith("__"):
                    private.append(f"{name} takes {target}.{taken}")
    return edges, private


def circles(edges: dict) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    sys.setrecursionlimit(10_000)

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                on.discard(w)
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                out.append(sorted(part))

    for v in edges:
        if v not in index:
            visit(v)
    return out


def test_no_import_circles():
    assert circles(graph()[0]) == []


def test_no_module_takes_another_modules_private_name():
    assert graph()[1] == []


def test_the_core_imports_no_ros():
    known = modules()
    core = {n: p for n, p in known.items() if not n.startswith(EDGE)}
    found = [
        f"{name} imports {target}"
        for name, path in core.items()
        for target, _ in imports(name, path.name == "__init__.py", path.read_text(), known)
        if target.split(".")[0] in ROS or target.startswith(EDGE)
    ]
    assert found == []


def test_the_checks_see_a_circle_a_private_name_and_ros():
    """The checks above can fail: a made-up graph with a circle; made-up imports."""
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": set()}) == [["a", "b", "c"]]
    known = {"cloth_sim.x", "cloth_sim.y", "cloth_sim.sub"}
    assert imports("cloth_sim.x", False, "from .y import _hidden\n", known) == [
        ("cloth_sim.y", "_hidden")
    ]
    assert imports("cloth_sim.sub", True, "from .. import y\nimport rclpy\n", known) == [
        ("cloth_sim.y", None),
        ("rclpy", None),
    ]


def function_imports(source: str) -> list[tuple[int, str]]:
    """``(line, module)`` of every import of a cloth_sim module inside a function of ``source``
    (a relative import, or an absolute one of ``cloth_sim``)."""
    found = []
    for fn in ast.walk(ast.parse(source)):
        if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for node in ast.walk(fn):
            if isinstance(node, ast.ImportFrom) and (
                node.level or (node.module or "").split(".")[0] == "cloth_sim"
            ):
                found.append((node.lineno, "." * node.level + (node.module or "")))
            elif isinstance(node, ast.Import):
                found += [
                    (node.lineno, a.name) for a in node.names if a.name.startswith("cloth_sim")
                ]
    return found


#: the layers the model is built from: nothing here imports the model or anything above it
BELOW_MODEL = {
    "cloth_sim.kinds",
    "cloth_sim.kernel_cache",  # (numba only: the kernels of these layers end with it)
    "cloth_sim.lazy",
    "cloth_sim.parameters",
    "cloth_sim.materials",
    "cloth_sim.materials.fabric",
    "cloth_sim.materials.library",
    "cloth_sim.materials.discretize",
    "cloth_sim.physics",
    "cloth_sim.physics.mesh",
    "cloth_sim.physics.bending",
    "cloth_sim.contact",
    "cloth_sim.contact.geometry",
    "cloth_sim.constraints",
    "cloth_sim.constraints.grippers",
}


def test_the_core_imports_at_the_top():
    """An import of the package's own modules inside a function of the core is a circle dodged
    (the core's lazy loads are third-party: a mesh reader, a URDF parser); the edges (the command
    line, the benchmarks, the adapters) may load a subcommand's modules when it runs."""
    known = modules()
    found = [
        f"{name}:{line} imports {target}"
        for name, path in known.items()
        if not name.startswith(EDGE)
        for line, target in function_imports(path.read_text())
    ]
    assert found == []


def test_the_model_imports_only_the_layers_below_it():
    """``cloth_sim.model`` and everything it imports, transitively, stay below it: the model takes
    its materials and meshes from there, never from the simulator's layers."""
    edges = graph()[0]
    reached, todo = set(), ["cloth_sim.model"]
    while todo:
        for target in edges[todo.pop()]:
            if target not in reached:
                reached.add(target)
                todo.append(target)
    assert reached <= BELOW_MODEL, sorted(reached - BELOW_MODEL)
    assert "cloth_sim.model" not in reached


def test_the_function_import_check_sees_one():
    source = "def f():\n    from .model import ClothModel\n    import numpy\n"
    assert function_imports(source) == [(2, ".model")]


#: the most parameters a function takes (``self`` and ``cls`` not counted); a kernel takes named
#: bundles (NamedTuples of its arrays, e.g. ``contact.collision_tree.Primitives``) instead of
#: long positional lists
MOST_PARAMETERS = 12

#: the functions that still take more, with how many: the house issue's debt, listed so that it
#: only shrinks (a function may leave this list, never join it or grow). (Helpers inlined into a
#: hot loop take whole arrays, not bundles of them: a bundle's fields read in a hot inlined helper
#: cost numba a reference count each, measured 1.7× on the self-collision tree.)
LONG_SIGNATURES = {
    "cloth_sim.simulator:Simulator.__init__": 17,
    "cloth_sim.envs.cloth_env:ClothEnv.__init__": 13,
    "cloth_sim.cuda.simulator:CudaSimulator.__init__": 13,
}


def parameter_counts(source: str) -> dict[str, int]:
    """``{qualified name: parameters}`` for every function and method in ``source`` (``self``
    and ``cls`` not counted; ``*args`` and ``**kwargs`` count one each)."""
    out = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = child.args
                names = [p.arg for p in a.posonlyargs + a.args] + [p.arg for p in a.kwonlyargs]
                n = len(names) + (a.vararg is not None) + (a.kwarg is not None)
                if isinstance(node, ast.ClassDef) and names[:1] in (["self"], ["cls"]):
                    n -= 1
                out[f"{prefix}{child.name}"] = n
                visit(child, f"{prefix}{child.name}.")

    visit(ast.parse(source), "")
    return out


def test_no_function_takes_more_than_twelve_parameters_but_the_listed_debt():
    found = {
        f"{name}:{func}": n
        for name, path in modules().items()
        for func, n in parameter_counts(path.read_text()).items()
        if n > MOST_PARAMETERS
    }
    new = {f: n for f, n in found.items() if f not in LONG_SIGNATURES}
    grown = {f: (LONG_SIGNATURES[f], n) for f, n in found.items() if n > LONG_SIGNATURES.get(f, n)}
    paid = sorted(set(LONG_SIGNATURES) - set(found))
    assert new == {}, f"functions over {MOST_PARAMETERS} parameters: bundle their arrays"
    assert grown == {}, "listed functions that took more parameters (listed, now)"
    assert paid == [], "functions now within the limit: take them off LONG_SIGNATURES"


def test_the_parameter_count_sees_methods_and_star_arguments():
    source = (
        "def f(a, b, *c, d, **e):\n    def g(x):\n        pass\n"
        "class K:\n    def m(self, x, y):\n        pass\n"
    )
    assert parameter_counts(source) == {"f": 5, "f.g": 1, "K.m": 2}
