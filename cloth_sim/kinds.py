"""The names and codes the model, the parameter schema, the scenes and the integrators share.

A leaf module: it imports nothing from cloth_sim, so the schema (:mod:`cloth_sim.parameters`) can
name the accepted values without importing the model or the integrators that use them.
"""

#: How a spring turns its length into a force.
LINEAR = 0  #: Hooke spring, pushes and pulls (Provot 1995, eq. 1.6 of the review).
TENSION_ONLY = 1  #: Choi & Ko type-1 interaction: pulls when stretched, nothing when compressed.
#: Choi & Ko type-2 interaction: immediate-buckling arc when compressed, Hooke when stretched.
BUCKLING = 2

GRID_FAMILIES = ("structural", "shear", "bend")
MESH_FAMILIES = ("structural", "bend")  # a triangle mesh: its edges, and across each interior edge
SPRING_FAMILY = "spring"  # the single family of a from_springs model
MODELS = ("provot", "choi_ko")
#: How the strain limit corrects (:mod:`cloth_sim.constraints.strain_limit`): Provot's
#: Gauss–Seidel passes, or one
#: projection of every over-stretched spring together
#: (:mod:`cloth_sim.constraints.strain_projection`)
STRAIN_LIMIT_METHODS = ("provot", "projection")
ORIENTATIONS = ("horizontal", "vertical")
#: Where a cloth is stepped (:mod:`cloth_sim.backends`): the host's cores, or an NVIDIA GPU
DEVICES = ("cpu", "cuda")

#: The integrators, in the order :func:`cloth_sim.integrators.available` lists them. The registry
#: (:mod:`cloth_sim.integrators`) refuses a class whose name is not here and checks, once every
#: method is registered, that each name here has its class: a new method adds its name here.
INTEGRATORS = (
    "explicit_euler",
    "symplectic_euler",
    "midpoint",
    "rk4",
    "verlet",
    "implicit_euler",
    "implicit_euler_prefactored",
    "kang",
    "liu2013",
    "xpbd",
    "vbd",
)
