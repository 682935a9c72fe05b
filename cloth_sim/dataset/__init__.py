"""Training data from the tasks: episodes of :mod:`cloth_sim.envs` under a policy, written as
LeRobot datasets (v3.0).

* :mod:`.lerobot` — the format: a writer that commits episode by episode (pyarrow and PyAV).
* :mod:`.rollout` — one episode of a task under the scripted or a random policy, as frames.
* :mod:`.engine` — ``cloth-sim dataset``: episodes on Ray, committed in order, resumable.
"""
