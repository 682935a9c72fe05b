"""Grid topology, model validation, scene files and the headless `cloth-sim run`."""

import ast
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import yaml

from cloth_sim import ClothModel, Simulator
from cloth_sim.cli import main as cli_main
from cloth_sim.scene import SceneError, available_scenes, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("model,bend_per_interior", [("provot", 2), ("choi_ko", 4)])
def test_grid_has_provot_and_choi_ko_springs(model, bend_per_interior):
    R, C = 5, 7
    m = ClothModel.grid(
        R, C, 0.1, 0.02, stiffness={"structural": 3, "shear": 2, "bend": 1}, model=model
    )
    fam = {name: np.count_nonzero(m.family == i) for i, name in enumerate(m.family_names)}
    assert fam["structural"] == (R - 1) * C + R * (C - 1)
    assert fam["shear"] == 2 * (R - 1) * (C - 1)
    expected_bend = (
        (R - 2) * C + R * (C - 2) + (2 * (R - 2) * (C - 2) if model == "choi_ko" else 0)
    )
    assert fam["bend"] == expected_bend
    # every spring's rest length matches its stencil: 1, √2, 2 (and 2√2 for Choi–Ko) spacings
    lengths = {round(L / 0.1, 6) for L in m.rest_lengths}
    assert lengths == ({1.0, 1.414214, 2.0} | ({2.828427} if model == "choi_ko" else set()))
    # particle (row, col) sits at (col·s, row·s, 0) with index row·cols + col
    np.testing.assert_allclose(m.positions[m.index(3, 4)], [0.4, 0.3, 0.0])
    assert np.all(m.stiffness[m.family == m.family_index("shear")] == 2)
    assert np.all(m.masses == 0.02)


def test_model_is_read_only_and_shared_by_simulators():
    m = ClothModel.grid(4, 4, 0.1, 0.01, stiffness=100.0, pinned=[(0, 0)])
    with pytest.raises(ValueError):
        m.positions[0, 0] = 1.0
    a, b = Simulator(m, integrator="rk4"), Simulator(m, integrator="verlet")
    a.set_stiffness("structural", 5.0)
    a.step(100)
    assert np.all(m.stiffness[m.family == 0] == 100.0)
    np.testing.assert_array_equal(b.positions, m.positions)


@pytest.mark.parametrize(
    "kwargs,match",
    [
        (dict(rows=1, cols=4), "rows and cols"),
        (dict(spacing=-1.0), "spacing"),
        (dict(particle_mass=0.0), "particle_mass"),
        (dict(stiffness={"structural": -1.0}), "stiffness.structural"),
        (dict(stiffness={"stretch": 1.0}), "unknown spring families"),
        (dict(pinned=[(9, 0)]), "outside"),
        (dict(model="baraff"), "unknown model"),
    ],
)
def test_grid_rejects_bad_input(kwargs, match):
    args = dict(rows=4, cols=4, spacing=0.1, particle_mass=0.01, stiffness=1.0)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        ClothModel.grid(**args)


def test_simulator_rejects_bad_parameters_and_keeps_its_state():
    sim = Simulator(ClothModel.grid(4, 4, 0.1, 0.01, stiffness=100.0), dt=1e-3)
    sim.step(10)
    x = sim.positions.copy()
    for bad in (
        lambda: setattr(sim, "dt", 0.0),
        lambda: setattr(sim, "dt", float("nan")),
        lambda: sim.set_stiffness("bend", -1.0),
        lambda: sim.set_stiffness("cloth", 1.0),
        lambda: setattr(sim, "gravity", (0, 0)),
        lambda: setattr(sim, "positions", np.zeros((3, 3))),
        lambda: setattr(sim, "velocities", np.full((16, 3), np.inf)),
        lambda: sim.set_integrator("leapfrog"),
    ):
        with pytest.raises(ValueError):
            bad()
    np.testing.assert_array_equal(sim.positions, x)
    assert sim.dt == 1e-3 and sim.integrator == "symplectic_euler"


def test_shipped_scenes_load_and_run():
    shipped = {"hanging", "hanging_provot", "curtain", "flag", "free_fall", "table", "fold"}
    assert shipped <= set(available_scenes())
    for name in sorted(shipped):
        scene = load_scene(name)
        sim = scene.build_simulator()
        assert sim.dt < sim.stable_dt()
        sim.advance(0.05)
        assert np.all(np.isfinite(sim.positions))
    assert "wind" in load_scene("flag").build_simulator().active_terms
    curtain = load_scene("curtain").build_model()
    assert np.count_nonzero(curtain.pinned) == curtain.cols


def test_a_scene_given_by_size_and_density_is_the_same_cloth_at_any_resolution():
    """A grid given by its extent and mass per area (fold's before it took a fabric): refined, the
    cloth keeps its size (so it still fits its floor), its mass (density × area, shared equally)
    and so its weight. fold itself, in a library fabric, keeps its size and the fabric's mass."""
    fold = load_scene("fold")
    scene = scene_from_dict(
        {
            "grid": {"rows": 24, "cols": 24, "orientation": "vertical"},
            "size": [1.0, 1.0],
            "density": 5.76,
            "stiffness": {"structural": 1000.0, "shear": 1000.0, "bend": 10.0},
        },
        source="dense.yaml",
    )
    w, h = scene.size
    for rows, cols in ((scene.rows, scene.cols), (64, 64), (17, 40)):
        model = scene.build_model(rows=rows, cols=cols)
        extent = sorted(np.ptp(model.positions, axis=0))[1:]
        assert extent == pytest.approx(sorted((w, h)), rel=1e-12)
        assert model.masses.sum() == pytest.approx(scene.grid_density * w * h, rel=1e-12)
        assert np.ptp(model.masses) == 0.0
        model = fold.build_model(rows=rows, cols=cols)
        extent = sorted(np.ptp(model.positions, axis=0))[1:]
        assert extent == pytest.approx(sorted(fold.size), rel=1e-12)
        area = fold.size[0] * fold.size[1]
        assert model.masses.sum() == pytest.approx(fold.material.density * area, rel=1e-12)
    # a spacing and a particle mass given to build_model are the cloth asked for
    asked = scene.build_model(rows=12, cols=12, spacing=0.05, particle_mass=0.02)
    assert np.ptp(asked.positions[:, 0]) == pytest.approx(11 * 0.05)
    assert asked.masses.sum() == pytest.approx(144 * 0.02)
    # given by a particle mass, a grid grows with its rows and cols at its spacing instead
    hanging = load_scene("hanging_provot")
    assert hanging.grid_density is None and hanging.material is None
    big = hanging.build_model(rows=40, cols=64)
    assert big.masses.sum() == pytest.approx(40 * 64 * hanging.particle_mass)
    assert np.ptp(big.positions[:, 0]) == pytest.approx(63 * hanging.spacing)


@pytest.mark.parametrize(
    "patch,field",
    [
        ({"grid": {"rows": 1, "cols": 4, "spacing": 0.1}}, "grid.rows"),
        ({"grid": {"rows": 4, "cols": 4}}, "grid.spacing"),
        ({"dt": "fast"}, "dt"),
        ({"dt": -1e-3}, "dt"),
        ({"integrator": "rk5"}, "integrator"),
        ({"stiffness": {"structural": -3}}, "stiffness.structural"),
        ({"pinned": [[0, 99]]}, "pinned[0]"),
        ({"pinned_edges": ["top"]}, "pinned_edges[0]"),
        ({"wind": {"direction": [1, 0], "strength": 1}}, "wind.direction"),
        ({"gravity": [0, 0, float("nan")]}, "gravity[2]"),
        ({"colour": "red"}, "colour"),
        ({"size": [1.0, 1.0], "grid": {"rows": 4, "cols": 4}, "density": 0.0}, "density"),
        ({"density": 1.0, "particle_mass": 0.01}, "density"),
    ],
)
def test_malformed_scene_names_the_file_and_field(patch, field):
    data = {"grid": {"rows": 4, "cols": 4, "spacing": 0.1}}
    data.update(patch)
    with pytest.raises(SceneError) as e:
        scene_from_dict(data, source="bad.yaml")
    assert str(e.value).startswith("bad.yaml:") and field in str(e.value)


def test_scene_file_errors(tmp_path):
    bad = tmp_path / "broken.yaml"
    bad.write_text("grid: {rows: 4, cols: [\n")
    with pytest.raises(SceneError, match="broken.yaml: not valid YAML"):
        load_scene(str(bad))
    with pytest.raises(SceneError, match="unknown scene 'nowhere'; available: .*hanging"):
        load_scene("nowhere")


def test_cli_run_prints_one_line_per_simulated_second(capsys):
    assert cli_main(["run", "--scene", "free_fall", "--duration", "2"]) == 0
    lines = [l for l in capsys.readouterr().out.splitlines() if l.startswith("t=")]
    assert len(lines) == 2
    assert "symplectic_euler" in lines[0] and "max_strain=" in lines[0] and "E_kin=" in lines[0]
    assert cli_main(["run", "--scene", "nowhere"]) == 2


def _imports(path):
    for node in ast.walk(ast.parse(path.read_text())):
        names = (
            [a.name for a in node.names]
            if isinstance(node, ast.Import)
            else ([node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 else [])
        )
        yield from (n.split(".")[0] for n in names)


def test_core_imports_no_ros():
    # the physics core: everything but the ROS adapter, the bag tools, the sweeps, the Gymnasium
    # tasks, the datasets and the benchmarks' front ends
    core = [
        p
        for p in (ROOT / "cloth_sim").rglob("*.py")
        if p.relative_to(ROOT).parts[1]
        not in ("ros", "bag", "bench", "sweep", "envs", "dataset", "cli.py")
    ]
    allowed = {
        "numpy",
        "scipy",
        "numba",
        "yaml",
        "cholespy",
        "qdldl",
        "trimesh",
        "yourdfpy",
        "lxml",
        "cloth_sim",
    }  # + the mesh reader; the URDF library and its XML parser (cloth_sim.robot)
    assert len(core) > 8
    for path in core:
        for top in _imports(path):
            assert top in allowed or top in sys.stdlib_module_names, f"{path.name} imports {top}"
    # the sweeps run headless: the core, the bag writer, Ray, pyarrow and a progress bar, no ROS
    sweep = list((ROOT / "cloth_sim" / "sweep").glob("*.py"))
    assert len(sweep) >= 4
    for path in sweep:
        for top in _imports(path):
            assert top in allowed | {"ray", "pyarrow", "tqdm"} or top in sys.stdlib_module_names, (
                f"sweep/{path.name} imports {top}"
            )
    # the Gymnasium tasks: the core and gymnasium, no ROS
    envs = list((ROOT / "cloth_sim" / "envs").glob("*.py"))
    assert len(envs) >= 6
    for path in envs:
        for top in _imports(path):
            assert top in allowed | {"gymnasium"} or top in sys.stdlib_module_names, (
                f"envs/{path.name} imports {top}"
            )
    # the datasets: the tasks, the sweeps, pyarrow, PyAV, Ray and a progress bar, no ROS
    dataset = list((ROOT / "cloth_sim" / "dataset").glob("*.py"))
    assert len(dataset) >= 4
    for path in dataset:
        for top in _imports(path):
            ok = allowed | {"gymnasium", "pyarrow", "av", "ray", "tqdm"}
            assert top in ok or top in sys.stdlib_module_names, (
                f"dataset/{path.name} imports {top}"
            )
    for path in (ROOT / "cloth_sim" / "bag" / "cdr.py", ROOT / "cloth_sim" / "settings.py"):
        for top in _imports(path):
            assert top in allowed or top in sys.stdlib_module_names, f"{path.name} imports {top}"
    # bag storage (info, reindex) works without ROS; only record/play/bench talk to the graph
    store = ROOT / "cloth_sim" / "bag" / "store.py"
    for top in _imports(store):
        assert top in {"yaml", "mcap"} or top in sys.stdlib_module_names, f"store.py imports {top}"


def test_package_xml_declares_every_runtime_dependency():
    root = ET.parse(ROOT / "package.xml").getroot()
    assert root.get("format") == "3" and root.findtext("name") == "cloth_sim"
    deps = {e.text for e in root if e.tag in ("depend", "exec_depend")}
    assert {
        "python3-numpy",
        "python3-scipy",
        "python3-numba",
        "python3-yaml",
        "python3-cholespy-pip",
        "python3-qdldl-pip",
    } <= deps
    # the keys rosdistro lacks are defined by the package's own rosdep file
    rules = yaml.safe_load((ROOT / "rosdep" / "cloth_sim.yaml").read_text())
    pip_keys = {
        e.text
        for e in root
        if e.tag in ("depend", "exec_depend", "test_depend", "doc_depend")
        and e.text.endswith("-pip")
    }
    assert {"python3-numba", "python3-cholespy-pip"} | pip_keys <= set(rules)
    assert "python3-pytest" in {e.text for e in root.findall("test_depend")}
    # ament_cmake: the package generates msg/Stats.msg; its Python code is installed by
    # CMakeLists.txt
    assert root.find("export/build_type").text == "ament_cmake"
    # rosdoc2 builds the site from docs/ (rosdoc2.yaml)
    assert root.findtext("export/rosdoc2") == "rosdoc2.yaml"
    assert (ROOT / "rosdoc2.yaml").exists() and (ROOT / "docs" / "conf.py").exists()
    assert root.findtext("member_of_group") == "rosidl_interface_packages"
    assert {"ament_cmake", "ament_cmake_python", "rosidl_default_generators"} <= {
        e.text for e in root.findall("buildtool_depend")
    }
    assert {
        "rclpy",
        "sensor_msgs",
        "visualization_msgs",
        "diagnostic_msgs",
        "std_srvs",
        "rosidl_default_runtime",
    } <= deps
    cmake = (ROOT / "CMakeLists.txt").read_text()
    assert 'rosidl_generate_interfaces(${PROJECT_NAME}\n  "msg/Stats.msg"' in cmake
    assert "install(PROGRAMS scripts/cloth_sim_node" in cmake
    assert os.access(ROOT / "scripts" / "cloth_sim_node", os.X_OK)


def test_console_script_is_installed():
    out = subprocess.run(
        [str(Path(sys.executable).parent / "cloth-sim"), "--help"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0 and "run" in out.stdout


def test_a_scene_passes_the_simulator_options_on_and_refuses_unknown_ones():
    """``build_simulator`` forwards the strain limit's options (it once dropped them, and a
    benchmark's "Provot alone" row ran with the attachments on) and refuses a key it does not know
    instead of ignoring it."""
    scene = load_scene("hanging_provot")
    sim = scene.build_simulator(
        rows=8, cols=8, strain_limit=0.1, strain_limit_passes=3, strain_limit_long_range=False
    )
    assert sim._strain.passes == 3 and sim._strain.long_range is False
    with pytest.raises(TypeError, match="unknown scene override.*strain_limit_pases"):
        scene.build_simulator(rows=8, cols=8, strain_limit_pases=3)
