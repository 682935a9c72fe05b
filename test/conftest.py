"""What every layer's tests share: one BLAS thread, and the seeded random generator."""

import os
import sys
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# the helpers every layer shares (malformed_scenes) import by name, as each folder's own do
sys.path.insert(0, str(Path(__file__).resolve().parent))


@pytest.fixture
def rng():
    return np.random.default_rng(12345)
