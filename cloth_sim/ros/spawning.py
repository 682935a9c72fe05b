"""``spawn_entity``, ``spawn_entities``, ``get_spawnables`` of the ROS simulation standard: a
collider from a ``cloth_sim://<shape>?…`` URI or a YAML ``resource_string`` (a scene's collider
mapping), or a URDF robot (:mod:`.robot_spawn`), placed at the request's ``initial_pose``; and the
spawned colliders' poses at spawn, which ``reset_simulation`` puts back or removes
(:mod:`.sim_interfaces`)."""

from __future__ import annotations

import itertools
from urllib.parse import parse_qsl

import numpy as np
import yaml
from simulation_interfaces import srv
from simulation_interfaces.msg import Result, Spawnable, SpawnResult

from ..contact.colliders import KINDS
from ..scene import GRIPPER_NAME, SceneError, SceneValidator
from . import robot_spawn
from .entities import Entities
from .messages import checked_pose, result

#: spawn_entity's URI scheme: ``cloth_sim://<shape>?<field>=<value>&…`` (a vector as ``x,y,z``)
SCHEME = "cloth_sim"
#: what each shape needs besides its pose (initial_pose places it), with the defaults used when
#: a URI or resource does not give them
SPAWN_DEFAULTS = {
    "plane": {"normal": [0.0, 0.0, 1.0]},
    "sphere": {"center": [0.0, 0.0, 0.0]},
    "box": {"center": [0.0, 0.0, 0.0]},
    "capsule": {},
}
SPAWNABLES = {
    "sphere": "cloth_sim://sphere?radius=0.1&friction=0.3",
    "box": "cloth_sim://box?half_extents=0.2,0.2,0.02&friction=0.5",
    "capsule": "cloth_sim://capsule?a=0,0,-0.1&b=0,0,0.1&radius=0.02",
    "plane": "cloth_sim://plane?normal=0,0,1&friction=0.5",
}


class Spawner:
    """The spawning services over the node's ``session`` (its simulator), ``manipulation`` (pose
    frames, twists, the colliders' topics) and ``entities`` (the names taken)."""

    def __init__(self, session, manipulation, entities: Entities):
        self.session, self.manipulation, self.entities = session, manipulation, entities
        #: the colliders spawned through spawn_entity: ``{name: (position, orientation) at spawn}``
        #: (reset with SCOPE_SPAWNED removes them; SCOPE_STATE alone puts them back there)
        self.spawned: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        #: per shape, the serial number of the next generated name (never one used before)
        self._serials: dict[str, itertools.count] = {}

    def spawn_entity(self, request, response):
        """A collider from ``uri`` (``cloth_sim://<shape>?…``) or ``resource_string`` (YAML: a
        scene's collider mapping), placed at ``initial_pose``."""
        response.result, response.entity_name = self.spawn(request)
        return response

    def spawn_entities(self, request, response):
        """Each request as ``spawn_entity`` would take it, in order; ENTITIES_SPAWN_FAILED when any
        failed (the others are spawned all the same, as the standard says)."""
        for one in request.spawn_requests:
            r, name = self.spawn(one, one.entity_resource)
            response.results.append(SpawnResult(result=r, entity_name=name))
        failed = [i for i, r in enumerate(response.results) if r.result.result != Result.RESULT_OK]
        response.result = (
            result()
            if not failed
            else result(
                srv.SpawnEntities.Response.ENTITIES_SPAWN_FAILED,
                f"spawn_requests {failed} failed (see results)",
            )
        )
        return response

    def spawn(self, request, resource=None) -> tuple[Result, str]:
        """``(result, entity name)`` of spawning what ``request`` describes (its ``uri`` and
        ``resource_string``, or those of ``resource``): a URDF robot (:func:`.robot_spawn.spawn`)
        or a collider."""
        resource = resource or request
        if robot_spawn.is_urdf(resource):
            return robot_spawn.spawn(self, request, resource)
        code, message, collider = self._collider_from(request, resource)
        if collider is None:
            return result(code, message), ""
        self.session.sim.add_collider(collider)
        self.spawned[collider.name] = (collider.position.copy(), collider.orientation.copy())
        self.manipulation.colliders_changed()
        name = f"collider/{collider.name}"
        return result(
            Result.RESULT_OK,
            f"spawned {type(collider).__name__.lower()} {name} (also "
            f"addressed as {collider.name!r})",
        ), name

    def _collider_from(self, request, resource):
        """``(code, message, collider)``: the collider a spawn request describes, or the standard's
        code and the reason (collider ``None``)."""
        R = srv.SpawnEntity.Response
        if not resource.uri and not resource.resource_string:
            return (
                R.NO_RESOURCE,
                "give uri (cloth_sim://<shape>?…) or resource_string (YAML)",
                None,
            )
        if request.entity_namespace:
            return (
                Result.RESULT_FEATURE_UNSUPPORTED,
                f"entity_namespace = "
                f"{request.entity_namespace!r}: cloth_sim's colliders have no ROS interfaces "
                f"of their own to put under a namespace; leave it empty",
                None,
            )
        if resource.uri:
            spec = parse_uri(resource.uri)
            if isinstance(spec, str):
                return R.UNSUPPORTED_FORMAT, spec, None
        else:
            try:
                spec = yaml.safe_load(resource.resource_string)
            except yaml.YAMLError as e:
                return R.RESOURCE_PARSE_ERROR, f"resource_string is not YAML ({e})", None
            if not isinstance(spec, dict) or spec.get("type") not in SPAWN_DEFAULTS:
                return (
                    R.UNSUPPORTED_FORMAT,
                    "resource_string must be a mapping with type: plane, "
                    "sphere, box or capsule, and that shape's fields",
                    None,
                )
        kind = spec["type"]
        spec = {**SPAWN_DEFAULTS[kind], **spec}
        # the name: the request's, else the resource's own (as the standard says)
        name = request.name or (spec.get("name") if isinstance(spec.get("name"), str) else "")
        if name and not GRIPPER_NAME.fullmatch(name):  # the rule every entity name follows
            return (
                R.NAME_INVALID,
                f"name = {name!r}: expected ASCII letters, digits and _ (not "
                f"starting with a digit, at most 64): it names the collider's topic and frame",
                None,
            )
        try:
            kind, kw = SceneValidator("spawn_entity").collider(0, {**spec, "name": name or kind})
        except SceneError as e:
            return R.RESOURCE_PARSE_ERROR, str(e).replace("colliders[0].", ""), None
        position, orientation, problem = checked_pose(
            request.initial_pose.pose,
            request.initial_pose.header.frame_id,
            self.manipulation.pose_frames(),
            prefix="initial_pose.",
        )
        if problem:
            return R.INVALID_POSE, problem, None
        if not name and not request.allow_renaming:
            return (
                R.NAME_INVALID,
                "name is empty (and the resource names none) while "
                "allow_renaming is false: give a name, or allow_renaming: true for a generated "
                "one",
                None,
            )
        taken = self.entities.taken()
        if name in taken and not request.allow_renaming:
            return (
                R.NAME_NOT_UNIQUE,
                f"an entity named {name!r} exists (allow_renaming: false)",
                None,
            )
        if not name or name in taken:  # a name never given before: <name or shape>_<k>
            serial = self._serials.setdefault(name or kind, itertools.count(1))
            name = next(c for c in (f"{name or kind}_{k}" for k in serial) if c not in taken)
        kw["name"] = name
        collider = KINDS[kind](**kw)
        # the pose: a sphere's or box's centre, a capsule's midpoint, a point on a plane (the
        # identity orientation keeps a plane's normal and a capsule's segment as built)
        collider.set_pose(position, orientation)
        return Result.RESULT_OK, "", collider

    def remove_collider(self, name: str) -> None:
        sim = self.session.sim
        index = next((i for i, c in enumerate(sim.colliders) if c.name == name), None)
        if index is not None:
            sim.remove_collider(index)
            self.manipulation.set_twist("collider", name, 0, 0)
            self.manipulation.colliders_changed()
        self.spawned.pop(name, None)

    def get_spawnables(self, request, response):
        response.spawnables = [
            Spawnable(
                uri=uri,
                description=f"a {kind} collider (fields as in a "
                f"scene file; initial_pose places it)",
            )
            for kind, uri in SPAWNABLES.items()
        ]
        # sources the simulator does not know are named, and do not hinder success (the standard)
        response.result = result(
            Result.RESULT_OK,
            ""
            if not request.sources
            else (
                f"sources not recognised: {', '.join(request.sources)} (cloth_sim's spawnables "
                "are its "
                f"collider shapes)"
            ),
        )
        return response


def parse_uri(uri: str):
    """``{type, fields…}`` of a ``cloth_sim://<shape>?<field>=<value>&…`` URI (numbers, and vectors
    as ``x,y,z``), or the reason it is not one (a string)."""
    # (by hand: an underscore is no URI scheme character for urllib)
    shape, _, query = uri[len(SCHEME) + 3 :].partition("?")
    if not uri.startswith(f"{SCHEME}://") or shape not in SPAWN_DEFAULTS:
        return (
            f"uri = {uri!r}: expected {SCHEME}://<shape>?<field>=<value>&… with shape one of "
            f"{', '.join(SPAWN_DEFAULTS)} (get_spawnables lists examples)"
        )
    spec = {"type": shape}
    for key, value in parse_qsl(query, keep_blank_values=True):
        try:
            numbers = [float(v) for v in value.split(",")]
        except ValueError:
            return f"uri field {key} = {value!r}: expected a number or numbers separated by commas"
        spec[key] = numbers[0] if len(numbers) == 1 else numbers
    return spec
