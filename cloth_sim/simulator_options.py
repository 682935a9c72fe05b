"""Parameter values as a simulator's options, in one place.

Which :class:`~cloth_sim.simulator.Simulator` option a parameter feeds is said by the parameter
itself (:attr:`~cloth_sim.parameters.Param.simulator`); this module reads it from there to build a
simulator's options (:func:`options`: the node's start and rebuilds, ``cloth_sim.settings``, and
:meth:`~cloth_sim.scene.Scene.build_simulator`) and to change a running one (:func:`apply`: the
node's live parameters). Where an option is not one value as it is, its composition is here: the
wind from its strength and direction, the strain limit's 0 for off, and the integrator's options
from ``vbd.*`` with the time budget that ``vbd.fit_tick`` gives a step.

A new live parameter is one :class:`~cloth_sim.parameters.Param` with ``simulator=`` naming the
option (the simulator's keyword and its settable attribute); nothing here changes.
"""

from __future__ import annotations

import numpy as np

from .parameters import SCHEMA

#: the share of a step's part of the tick that vbd's iterations may take under ``vbd.fit_tick``
#: (the rest of the step, its stages and the publishing take the other part)
FIT_SHARE = 0.6


def vbd_options(iterations: int, tolerance: float, substeps: int) -> dict:
    """The vbd integrator's options from a scene's or the node's values: ``vbd.iterations`` (0:
    as many as each step needs to reach ``vbd.tolerance``), ``vbd.tolerance`` and
    ``vbd.substeps`` (0: as many as the cloth asks, ``"auto"``). Both 0, vbd chooses its work as
    it does from Python without options: substeps from the cloth, or a direct solve where that
    is cheaper (:class:`~cloth_sim.integrators.vbd.VBD`)."""
    options = {"tolerance": tolerance}
    if iterations:
        options["iterations"] = iterations
        options["substeps"] = substeps or "auto"
    elif substeps:
        options["substeps"] = substeps
    return options


def wind(values: dict):
    """The wind vector (strength × direction), ``None`` when it is off."""
    w = values["wind.strength"] * np.asarray(values["wind.direction"], dtype=float)
    return w if np.any(w) else None


def integrator_options(values: dict) -> dict:
    """The integrator's options: vbd's iterations, tolerance and substeps, and under
    ``vbd.fit_tick`` a time budget a step (:data:`FIT_SHARE` of a step's share of the tick at the
    target ``real_time_factor``); none for the other methods."""
    if values["integrator"] != "vbd":
        return {}
    options = vbd_options(
        values["vbd.iterations"], values["vbd.tolerance"], values["vbd.substeps"]
    )
    if values.get("vbd.fit_tick") and values.get("real_time_factor", 0.0) > 0:
        options["time_budget"] = FIT_SHARE * values["dt"] / values["real_time_factor"]
    return options


def _strain_limit(values: dict):
    return values["strain_limit"] or None  # (0: off)


#: the options that are not one parameter's value as it is: how each is made, and the values it
#: needs (the integrator's options read the method and the step too; ``vbd.fit_tick`` and
#: ``real_time_factor``, the node's own, may be missing: no time budget)
_COMPOSED = {
    "wind": (wind, ("wind.strength", "wind.direction")),
    "strain_limit": (_strain_limit, ("strain_limit",)),
    "integrator_options": (
        integrator_options,
        ("integrator", "dt", "vbd.iterations", "vbd.tolerance", "vbd.substeps"),
    ),
}

#: option → the parameters that feed it, in the schema's order
FED_BY: dict[str, tuple[str, ...]] = {}
for _p in SCHEMA.values():
    if _p.simulator is not None:
        FED_BY[_p.simulator] = (*FED_BY.get(_p.simulator, ()), _p.name)
#: the options a running simulator takes (fed by a live parameter; ``device`` rebuilds)
LIVE = tuple(o for o, names in FED_BY.items() if any(SCHEMA[n].apply == "live" for n in names))


def options(values: dict) -> dict:
    """The simulator's options that ``values`` (parameter name → checked value) set: each option
    whose values are all there (:data:`_COMPOSED` says which a composed option needs)."""
    out = {}
    for option, names in FED_BY.items():
        compose, needed = _COMPOSED.get(option, (None, names))
        if all(n in values for n in needed):
            out[option] = compose(values) if compose else values[names[0]]
    return out


def _same(a, b) -> bool:
    if a is None or b is None:
        return a is b
    if isinstance(a, dict) or isinstance(b, dict):
        return a == b
    return bool(np.array_equal(np.asarray(a), np.asarray(b)))


def apply(sim, new: dict, old: dict) -> list[str]:
    """Change the running ``sim`` to the live values of ``new`` (a whole configuration; ``old``
    the one it runs with): each spring family's stiffness and damping that changed, then each
    live option (:data:`LIVE`) that differs from the simulator's own, by setting the attribute, in
    the schema's order; last the method and its options together
    (:meth:`~cloth_sim.simulator.Simulator.set_integrator`), if either differs. Returns the options
    set."""
    for f in sim.model.family_names:
        for kind, setter in (("stiffness", sim.set_stiffness), ("damping", sim.set_damping)):
            name = f"{kind}.{f}"
            if new[name] != old[name]:
                setter(f, new[name])
    wanted = options(new)
    changed = []
    for option in LIVE:
        if option in ("integrator", "integrator_options"):
            continue  # (last, together)
        if not _same(wanted[option], getattr(sim, option)):
            setattr(sim, option, wanted[option])
            changed.append(option)
    method, opts = wanted["integrator"], wanted["integrator_options"]
    if method != sim.integrator or opts != sim.integrator_options:
        sim.set_integrator(method, **opts)  # (made for the step, the forces and stages now set)
        changed.append("integrator")
    return changed
