"""Parallel sweeps and datasets: a spec (:mod:`.spec`), one headless run (:mod:`.run`, with its
script, :mod:`.script`) and the Ray driver (:mod:`.engine`). ``cloth-sim sweep SPEC.yaml -o OUT``
runs them; nothing here loads ROS's graph, and Ray is imported only when runs are to be run."""

from .spec import Spec, SpecError, load_spec, run_id, spec_from_dict

__all__ = ["Spec", "SpecError", "load_spec", "run_id", "spec_from_dict"]
