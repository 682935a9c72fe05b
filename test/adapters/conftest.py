"""What the adapters' tests share: a Gymnasium task's initial-state cache, one per test module
(the variations are generated once a module)."""

import pytest


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return str(tmp_path_factory.mktemp("initial_states"))
