"""The scene hashes that a step-changing commit is checked with (``cloth-sim bench hashes``)."""

import numpy as np
import pytest

from cloth_sim.bench.scene_hashes import scene_hashes, state_hash
from cloth_sim.scene import load_scene


def test_one_bit_of_one_coordinate_changes_the_hash():
    sim = load_scene("hanging").build_simulator()
    sim.step(2)
    before = state_hash(sim)
    x = sim.positions.copy()
    x[5, 1] = np.nextafter(x[5, 1], np.inf)
    sim.positions = x
    assert state_hash(sim) != before


def test_a_scene_hashes_the_same_run_to_run_on_its_own_method_and_on_vbd():
    first = scene_hashes(steps=3, scenes=["hanging"])
    assert [(s, i) for s, i, _ in first] == [("hanging", "symplectic_euler"), ("hanging", "vbd")]
    assert all(len(h) == 16 and int(h, 16) >= 0 for _, _, h in first)
    assert first[0][2] != first[1][2]
    assert scene_hashes(steps=3, scenes=["hanging"]) == first


def test_steps_below_one_are_refused():
    with pytest.raises(ValueError, match="steps must be >= 1"):
        scene_hashes(steps=0, scenes=["hanging"])
