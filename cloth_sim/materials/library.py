"""The library of named fabrics: measured sets, converted to :class:`~.fabric.Fabric` in code.

**Wang, Ramamoorthi & O'Brien (2011)**, "Data-Driven Elastic Models for Cloth: Modeling and
Measurement" (ACM TOG 30(4):71): ten fabrics measured in tension, shear and bending and published
as ARCSim material files (``materials/*.json`` of ARCSim 0.2 and its forks, e.g. the Berkeley
Garment Library). Each file holds ``density`` (kg/m²), ``stretching`` (6 rows of four
coefficients: row 0 at zero strain, rows 1–5 at 1/6 strain in five directions) and ``bending``
(3 directions × 5 curvature samples). What is kept here is their small-strain, small-curvature
limit, converted by :func:`from_arcsim`; the raw rows are below, so the conversion can be checked.

* **Stretching.** ARCSim's membrane energy per area is ``½(k0 G00² + k2 G11² + 2 k1 G00 G11 +
  k3 G01²)`` in the Green strain ``G``, with ``k = 2 × row 0`` at zero strain (``dde.cpp``
  doubles the tabulated values; negative ones are clamped to 0 there too). Against ``½C11ε00² +
  ½C22ε11² + C12ε00ε11 + 2C66ε01²``: ``C11 = 2·r0``, ``C22 = 2·r2``, ``C12 = 2·r1``, ``C66 =
  r3/2``. The strip-test stiffnesses are then ``stretch_warp = C11 − C12²/C22`` and
  ``stretch_weft = C22 − C12²/C11``, ``poisson = C12/C22`` and ``shear = C66``. Warp is the
  material ``u`` axis (ARCSim's first).
* **Bending.** ARCSim's energy of an edge is ``ke·l²θ²/(8(A0 + A1))`` (``physics.cpp``); on the
  near-equilateral meshes its remesher makes, a cylindrical bend of curvature ``κ`` sums to
  ``ke·κ²/12`` per area over the three edge directions, which is ``½Gκ²`` for ``G = ke/6``. The
  sample of zero curvature is taken; an edge along ``u`` (row 0) bends the cloth across the weft
  (weft value), one along ``v`` (row 2) along the warp. (On a mesh of right triangles the same
  ``ke`` would be ``G = ke/4``: the measured ``ke`` carries this factor-1.5 uncertainty of
  ARCSim's discretisation.)

The generic names ``denim``, ``cotton`` and ``polyester`` are the measured fabrics closest to them
(by fibre content). Silk and wool are not here: no published set within reach gave all of their
density, tensile, shear and bending values (Penava et al. 2014 give E, ν and density of wool and
cotton but no bending).
"""

from __future__ import annotations

from .fabric import Fabric

WANG_2011 = (
    "Wang, Ramamoorthi & O'Brien 2011, Data-Driven Elastic Models for Cloth (ARCSim material "
    "file {file}.json; {use}, {fibre}); small-strain limit converted by "
    "cloth_sim.materials.library.from_arcsim"
)

#: name -> (typical use, fibre content, density, stretching row 0, bending column 0 of rows 0-2)
#: as published in ARCSim's material files
ARCSIM_DATA = {
    "11oz-black-denim": (
        "jeans",
        "99% cotton 1% spandex",
        0.324,
        (205.352005, 10.234077, 1013.88629, 53.387184),
        (64.196457e-6, 73.384567e-6, 96.951576e-6),
    ),
    "camel-ponte-roma": (
        "jacket",
        "60% polyester 40% rayon",
        0.284,
        (31.146198, -12.802702, 44.028667, 31.896357),
        (36.348366e-6, 33.013252e-6, 37.157593e-6),
    ),
    "gray-interlock": (
        "t-shirt",
        "60% cotton 40% polyester",
        0.187,
        (16.593832, -14.695990, 34.477123, 36.860302),
        (23.191698e-6, 24.749964e-6, 14.267624e-6),
    ),
    "ivory-rib-knit": (
        "underwear",
        "95% cotton 5% spandex",
        0.276,
        (42.871021, -0.234556, 65.166023, 83.175644),
        (46.237591e-6, 30.015930e-6, 32.243889e-6),
    ),
    "navy-sparkle-sweat": (
        "sweater",
        "96% polyester 4% spandex",
        0.224,
        (12.486332, -19.875324, 3.272434, 17.616289),
        (59.469658e-6, 40.072277e-6, 45.625023e-6),
    ),
    "pink-ribbon-brown": (
        "blanket",
        "100% polyester",
        0.228,
        (151.503906, 106.028160, 244.830673, 30.250183),
        (117.070122e-6, 87.509773e-6, 59.774277e-6),
    ),
    "royal-target": (
        "pants",
        "65% cotton 35% polyester",
        0.220,
        (2016.55456, 9.170511, 2034.97644, 104.759674),
        (125.409805e-6, 107.997696e-6, 125.409805e-6),
    ),
    "tango-red-jet-set": (
        "jacket",
        "100% polyester",
        0.113,
        (43.067627, 54.373299, 171.424835, 14.314700),
        (14.293814e-6, 21.951700e-6, 20.345654e-6),
    ),
    "white-dots-on-blk": (
        "tablecloth",
        "100% polyester",
        0.128,
        (2002.08618, 0.345588, 2027.48559, 19.189022),
        (51.713814e-6, 40.659470e-6, 31.282822e-6),
    ),
    "white-swim-solid": (
        "swimsuit",
        "87% nylon 13% spandex",
        0.204,
        (47.971176, 6.834521, 104.615456, 60.773663),
        (60.237942e-6, 58.803211e-6, 51.018833e-6),
    ),
}

#: the measured fabrics (the generic names are copies of some of them)
MEASURED = tuple(ARCSIM_DATA)

#: generic names -> the measured fabric standing for them
ALIASES = {
    "denim": "11oz-black-denim",
    "cotton": "ivory-rib-knit",
    "polyester": "white-dots-on-blk",
}


def from_arcsim(density: float, row0, bending0, source: str = "") -> Fabric:
    """A :class:`Fabric` from an ARCSim material's density, its zero-strain stretching row and the
    zero-curvature bending samples of its three directions (the module's note)."""
    r = [max(0.0, float(v)) for v in row0]  # dde.cpp clamps negative coefficients to 0
    c11, c12, c22, c66 = 2.0 * r[0], 2.0 * r[1], 2.0 * r[2], 0.5 * r[3]
    if c11 <= 0 or c22 <= 0:
        raise ValueError("from_arcsim: zero tensile coefficient")
    return Fabric(
        density=density,
        stretch=(c11 - c12 * c12 / c22, c22 - c12 * c12 / c11),
        shear=c66,
        bend=(bending0[2] / 6.0, bending0[0] / 6.0),
        poisson=min(c12 / c22, 0.49),
        source=source,
    )


def _build() -> dict[str, Fabric]:
    lib = {}
    for name, (use, fibre, density, row0, bend0) in ARCSIM_DATA.items():
        lib[name] = from_arcsim(
            density, row0, bend0, WANG_2011.format(file=name, use=use, fibre=fibre)
        )
    for alias, name in ALIASES.items():
        f = lib[name]
        lib[alias] = Fabric(**f.as_dict(), source=f"{name}: {f.source}")
    return lib


LIBRARY = _build()
