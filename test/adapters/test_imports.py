"""Every module of the package imports, the edges included (a benchmark or a backend no test of
its own imports still fails here, not in a user's hands). A module whose optional third-party
dependency is not installed (torch, newton, numba-cuda's wheels: their own requirements files) is
passed over; a name missing from the package itself is not."""

import importlib
import pkgutil

import cloth_sim


def test_every_module_of_the_package_imports():
    failed, passed_over = [], []
    for info in pkgutil.walk_packages(cloth_sim.__path__, "cloth_sim."):
        try:
            importlib.import_module(info.name)
        except ModuleNotFoundError as e:
            if e.name and not e.name.startswith("cloth_sim"):
                passed_over.append((info.name, e.name))  # an optional extra not installed
            else:
                failed.append(f"{info.name}: {e!r}")
        except Exception as e:  # an ImportError of a name, a SyntaxError, anything at import
            failed.append(f"{info.name}: {e!r}")
    assert failed == []
    assert len(passed_over) < 10, passed_over  # the extras are few: not the whole package


def test_the_check_sees_a_missing_name(tmp_path, monkeypatch):
    pkg = tmp_path / "fake_pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "broken.py").write_text("from cloth_sim.integrators.vbd import NO_SUCH_NAME\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        importlib.import_module("fake_pkg.broken")
    except ImportError as e:
        assert not isinstance(e, ModuleNotFoundError)
    else:
        raise AssertionError("a missing name imported")
