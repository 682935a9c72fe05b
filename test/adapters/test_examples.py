"""Every example under examples/ runs (each in its short form, --quick) and prints what it says it
does; the docs show these files, so a code sample that stops working fails here. The node's
examples run against a live node in test/ros/test_example_grasp.py and test_example_robot.py;
examples/learning/ needs the optional LeRobot extra (make bench-learning)."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = ROOT / "examples"
#: each example and lines its output must hold
EXPECTED = {
    "python_api.py": ["integrators: explicit_euler, symplectic_euler", "stable_dt", "holding"],
    "garment.py": ["2296 vertices", "landmarks: hem_left", "from_mesh: 2296 vertices"],
    "gymnasium_task.py": [
        "scripted fold: normalized performance 0.8",
        "frame (128, 128, 3)",
        "ClothFoldVectorEnv observations (4, 18) rewards (4,)",
    ],
    "depth_camera.py": ["depth (60, 80)", "triangles in view", "the centre pixel sees"],
    "sweep.py": ["runs by status: {'ok': 4}", "(complete)"],
    "contacts.py": ["closest to the ball's surface: 0.00", "after moving the ball"],
    "materials.py": [
        "denim: 0.324 kg/m²",
        "9×9: mass 0.0810 kg",
        "17×17: mass 0.0810 kg",
        "felt cantilever: bending length 2.85",
        "felt strip tensile: 800.",
        "'xpbd' does not take a material's bending",
    ],
    "gpu.py": [
        "; running on ",
        "one cloth on ",
        "converged: True",
        "4 worlds on ",
        "positions (4, 144, 3)",
        "world 1 reset: time 0.000 s, the others at 0.500 s",
    ],
    "robot.py": [
        "7 links with collisions",
        "closest the cloth came to a link: 1.00",
        "the hand holds",
    ],
}


def test_every_example_is_run_here_or_by_the_node_tests():
    here = {p.name for p in EXAMPLES.glob("*.py")}
    assert here == set(EXPECTED) | {"grasp_node.py", "robot_node.py"}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_the_example_runs(name, tmp_path):
    env = dict(os.environ, RAY_AUTH_MODE="disabled", MPLBACKEND="Agg")
    argv = [sys.executable, str(EXAMPLES / name), "--quick"]
    if name == "sweep.py":
        argv += ["-o", str(tmp_path / "sweep")]
    r = subprocess.run(argv, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    for line in EXPECTED[name]:
        assert line in r.stdout, (line, r.stdout)
