"""The standard interfaces no wheel has (interfaces/: simulation_interfaces, tf2_msgs), generated
for the venv by tools/build_interfaces.py, carry the released Jazzy packages' RIHS01 type hashes,
so a node here and any Jazzy install's clients agree on every type."""

import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GENERATED = ROOT / "build" / "interfaces" / "install" / "share"


def released() -> dict:
    rows = [
        line.split()
        for line in (ROOT / "interfaces" / "released_hashes.txt").read_text().splitlines()
        if line and not line.startswith("#")
    ]
    return dict(rows)


def generated() -> dict:
    out = {}
    for package in ("simulation_interfaces", "tf2_msgs"):
        for path in (GENERATED / package).rglob("*.json"):
            for entry in json.loads(path.read_text()).get("type_hashes", []):
                out[entry["type_name"]] = entry["hash_string"]
    return out


def test_every_generated_type_has_the_released_hash():
    want, got = released(), generated()
    assert len(want) == 117
    mine = {
        t: h for t, h in got.items() if t.split("/")[0] in ("simulation_interfaces", "tf2_msgs")
    }
    assert mine == want


def test_the_python_types_import_and_carry_the_hashes():
    from simulation_interfaces.action import SimulateSteps
    from simulation_interfaces.msg import Result, SimulatorFeatures
    from simulation_interfaces.srv import StepSimulation
    from tf2_msgs.msg import TFMessage

    assert StepSimulation.Request().steps == 1  # the released default
    assert Result.RESULT_OK == 1 and SimulatorFeatures.STEP_SIMULATION_ACTION == 33
    assert SimulateSteps.Goal().steps == 0 and TFMessage().transforms == []


@pytest.mark.parametrize("package", ["simulation_interfaces", "tf2_msgs"])
def test_colcon_on_a_real_install_leaves_the_vendored_copies_alone(package):
    assert (ROOT / "interfaces" / "COLCON_IGNORE").is_file()
    assert (ROOT / "interfaces" / package / "package.xml").is_file()
