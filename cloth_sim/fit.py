"""A fabric fitted to a recording: the material parameters whose simulation of a scene comes
closest to a recorded sequence of point clouds.

The recording is a sequence of point clouds (from a bag of ``sensor_msgs/PointCloud2``: the node's
``~/points``, or a depth camera's cloud in the simulation's frame; :mod:`cloth_sim.sweep.fit` reads
it): unorganised points with noise and holes, so the distance is a
**one-way Chamfer distance** from the recorded points to the simulated cloth's surface (each
recorded point's distance to the closest point of its triangles), averaged over the points and then
over the frames; the one-way **Hausdorff** distance (the largest of those) is reported beside it,
as Blanco-Mulero et al. (2024) report their real-versus-simulated cloth. Frame ``k`` is compared
with the simulation at the recording's time since its first message (the recording starts when the
scene does).

The parameters are the scene material's fields (``stretch``, ``shear``, ``bend``, ``density``,
``damping``), each searched as a factor on the scene's value over ``[1/span, span]`` in log
space, with the two of a warp–weft pair scaled together. The optimiser is SciPy's differential
evolution (derivative-free, population-based, deterministic for a seed): each generation's
candidates are independent simulations, spread over Ray's workers (``workers``, ``address``), and
the result does not depend on how many there are (the core takes any ``map``; the command line
gives it Ray's); its best candidate is then refined by
Nelder–Mead (SciPy's, serial).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np
import yaml
from scipy.optimize import differential_evolution, minimize

from .contact.triangle_meshes import TriangleMesh, mesh_distance, pack
from .kernel_cache import keep_true
from .materials import Fabric
from .scene import SceneError, load_scene
from .simulator import SimulationDiverged

#: the material fields a fit may search
PARAMETERS = ("stretch", "shear", "bend", "density", "damping")


def parse_params(text) -> list[str]:
    """``"stretch,bend"`` (or a list) → the names; an unknown one, or none, raises ``ValueError``
    naming it and the accepted ones."""
    names = [n.strip() for n in (text.split(",") if isinstance(text, str) else text) if n.strip()]
    if not names:
        raise ValueError(f"--params: expected one or more of {', '.join(PARAMETERS)}")
    for n in names:
        if n not in PARAMETERS:
            raise ValueError(
                f"--params: {n!r} is not a material parameter; expected {', '.join(PARAMETERS)}"
            )
    return list(dict.fromkeys(names))


@numba.njit(cache=True)
def _distances(bank, points, out):
    reals, ints, starts = bank
    for i in range(points.shape[0]):
        # the distance to the surface, unsigned (a closed cloth mesh has an inside)
        x, y, z = points[i, 0], points[i, 1], points[i, 2]
        out[i] = abs(mesh_distance(reals, ints, starts, 0, x, y, z)[0])


def one_way(recorded: np.ndarray, x: np.ndarray, triangles: np.ndarray) -> tuple[float, float]:
    """``(Chamfer, Hausdorff)``: the mean and the largest distance from each recorded point to
    the cloth's surface, its triangles (m; exact closest points, through the triangles'
    hierarchy)."""
    bank = pack([TriangleMesh(x, triangles, "cloth")])
    d = np.empty(len(recorded))
    _distances(bank, np.ascontiguousarray(recorded, dtype=np.float64), d)
    return float(d.mean()), float(d.max())


class Objective:
    """The mean one-way Chamfer distance of a candidate (log factors, one per parameter) over the
    recording; picklable, so Ray's workers each hold one (the scene loaded once per worker)."""

    def __init__(self, scene: str, params: list[str], times: np.ndarray, clouds: list):
        self.scene_ref, self.params = str(scene), list(params)
        self.times, self.clouds = np.asarray(times, float), clouds
        self._scene = None

    def scene(self):
        if self._scene is None:
            self._scene = load_scene(self.scene_ref)
        return self._scene

    def fabric(self, log_factors) -> Fabric:
        return self.scene().material.scaled(
            **{p: math.exp(v) for p, v in zip(self.params, log_factors)}
        )

    def distances(self, log_factors) -> tuple[float, float]:
        """``(mean Chamfer, largest Hausdorff)`` over the frames; ``(inf, inf)`` for a candidate
        whose simulation diverges."""
        scene = self.scene()
        sim = scene.build_simulator(material=self.fabric(log_factors))
        if sim.stable_dt() < sim.dt:  # an explicit method: the stiffer candidates need less
            sim.dt = 0.9 * sim.stable_dt()
        tris = sim.model.triangles
        chamfer, hausdorff = [], []
        try:
            for t, pts in zip(self.times, self.clouds):
                if t > sim.time:
                    sim.advance(t)
                c, h = one_way(pts, sim.positions, tris)
                chamfer.append(c)
                hausdorff.append(h)
        except SimulationDiverged:
            return math.inf, math.inf
        return float(np.mean(chamfer)), float(np.max(hausdorff))

    def __call__(self, log_factors) -> float:
        c, _ = self.distances(log_factors)
        return c if math.isfinite(c) else 1e3


@dataclass
class FitResult:
    params: dict  # name -> fitted value (a pair for stretch and bend)
    factors: dict  # name -> factor on the scene's value
    fabric: Fabric
    chamfer: float
    hausdorff: float
    start_chamfer: float
    evaluations: int
    wall: float
    workers: int
    frames: int
    points: int


def scene_with_material(scene_ref: str):
    """The scene ``scene_ref``; one without a material raises ``ValueError`` saying so."""
    scene = load_scene(scene_ref)
    if scene.material is None:
        raise ValueError(
            f"--scene {scene_ref}: it has no material: a fit searches a material's "
            f"{', '.join(PARAMETERS)}; give the scene a material: (a library name or mapping)"
        )
    return scene


def fit(
    times,
    clouds: list,
    scene: str,
    params,
    mapper=map,
    workers: int = 1,
    span: float = 3.0,
    generations: int = 12,
    population: int = 6,
    seed: int = 0,
    max_frames: int = 30,
    polish: int = 60,
) -> FitResult:
    """Fit ``params`` of ``scene``'s material to a recording: ``clouds[k]`` (points, m) seen at
    ``times[k]`` (s since the recording began; module docstring).
    ``mapper``: a ``map`` that evaluates a generation's candidates (the built-in one here; the
    command line, :mod:`cloth_sim.sweep.fit`, passes Ray's and ``workers`` says how many it has).
    ``span``: each factor is searched in ``[1/span, span]``; ``population`` × the number of
    parameters candidates a generation, at most ``generations``; at most ``max_frames`` frames
    of the recording, evenly picked, enter the distance; the best candidate is then refined by at
    most ``polish`` Nelder–Mead evaluations."""
    params = parse_params(params)
    scene_with_material(scene)
    if not (span > 1 and math.isfinite(span)):
        raise ValueError(f"span: expected a number > 1, got {span!r}")
    times = np.asarray(times, dtype=np.float64)
    if len(times) == 0 or len(times) != len(clouds):
        raise ValueError("fit: a recording of one or more clouds, each with its time")
    pick = np.unique(
        np.linspace(0, len(times) - 1, min(max_frames, len(times))).round().astype(int)
    )
    times, clouds = times[pick], [clouds[i] for i in pick]
    objective = Objective(scene, params, times, clouds)
    bounds = [(-math.log(span), math.log(span))] * len(params)
    t = time.perf_counter()
    res = differential_evolution(
        objective,
        bounds,
        strategy="best1bin",
        maxiter=generations,
        popsize=population,
        tol=0.0,
        atol=1e-5,  # 0.1 mm: the population agrees to well below the recording's noise
        seed=seed,
        polish=False,
        init="sobol",
        updating="deferred",
        workers=mapper,
    )
    # the best candidate refined by Nelder–Mead (derivative-free, in this process)
    local = minimize(
        objective,
        res.x,
        method="Nelder-Mead",
        options={"xatol": 1e-3, "fatol": 1e-6, "maxfev": polish},
    )
    best = local.x if local.fun <= res.fun else res.x
    wall = time.perf_counter() - t
    fabric = objective.fabric(best)
    chamfer, hausdorff = objective.distances(best)
    start, _ = objective.distances(np.zeros(len(params)))
    return FitResult(
        params={p: getattr(fabric, p) for p in params},
        factors={p: math.exp(v) for p, v in zip(params, best)},
        fabric=fabric,
        chamfer=chamfer,
        hausdorff=hausdorff,
        start_chamfer=start,
        evaluations=int(res.nfev + local.nfev),
        wall=wall,
        workers=workers,
        frames=len(times),
        points=int(sum(len(c) for c in clouds)),
    )


def write_scene(scene: str, fabric: Fabric, out) -> Path:
    """The scene file ``scene`` was loaded from with its ``material:`` replaced by ``fabric``'s
    fields (a mesh file path made absolute, so the new file loads from anywhere)."""
    src = load_scene(scene)
    if src.source == "<dict>":
        raise SceneError(f"--scene {scene}: not a scene file")
    data = yaml.safe_load(Path(src.source).read_text())
    data["material"] = {
        k: (list(v) if isinstance(v, tuple) else v) for k, v in fabric.as_dict().items()
    }
    data["name"] = f"{data.get('name', src.name)}_fitted"
    if "mesh" in data:
        data["mesh"]["file"] = str(src.mesh["file"])
    out = Path(out)
    out.write_text(
        f"# {src.name} with its material fitted to a recording by cloth-sim fit\n"
        + yaml.safe_dump(data, sort_keys=False)
    )
    return out


keep_true(__name__)  # (its kernels compile again when a file it imports changes)
