"""Every CUDA kernel compiles to PTX for sm_90 (H100, H200) in both precisions: the type checks and
lowering that numba-cuda's simulator, which runs the kernels as Python, never does."""

import numba
import numpy as np
import pytest
from numba import cuda

from cloth_sim import ClothModel
from cloth_sim.cuda import kernels as K
from cloth_sim.cuda.layout import Iterate, Run, Worlds, limits, topology

SM90 = (9, 0)


def signatures(real):
    """Each kernel's argument types as :class:`cloth_sim.cuda.worlds.CudaWorlds` launches it."""
    model = ClothModel.grid(4, 4, material="cotton", size=(0.2, 0.2), pinned=[(0, 0)])
    top, _ = topology(model, real)
    w, n, f = 2, model.n_particles, len(model.family_names)
    wor = Worlds(
        masses=np.ones((w, n), real),
        free=np.ones((w, n), np.int8),
        gravity=np.zeros((w, 3), real),
        wind=np.zeros((w, 3), real),
        windy=np.zeros(w, np.int8),
        drag=np.zeros(w, real),
        kfam=np.zeros((w, f), real),
        cfam=np.zeros((w, f), real),
        ckind=np.zeros((w, 1), np.int32),
        cpos=np.zeros((w, 1, 3), real),
        crot=np.zeros((w, 1, 3, 3), real),
        cpos0=np.zeros((w, 1, 3), real),
        crot0=np.zeros((w, 1, 3, 3), real),
        cgeo=np.zeros((w, 1, 4), real),
        cmu=np.zeros((w, 1), real),
        ncol=np.zeros(w, np.int32),
        tau=np.zeros(w, real),
        kc=np.zeros(w, real),
        gbox=np.zeros((1, 5), real),
        gdim=np.zeros((1, 4), np.int32),
        gval=np.zeros(8, real),
        cimp=np.zeros((w, n, 1, 6), real),
    )
    x = np.zeros((w, n, 3), real)
    flags = np.zeros(w, np.int8)
    it = Iterate(*([x] * 7), np.zeros((w, n), real), *([x] * 4), flags, flags)
    ty = numba.typeof
    r = ty(real(1))
    run = ty(Run(real(1e-3), real(2e-3 / 3), 1, 1, 1, 1, 10, 1e-2, 5, 0.8, 0.1, 20))
    lim = ty(limits(model, w, real))
    out = numba.float64[:, ::1]
    return {
        K.explicit_substep: (ty(top), ty(wor), ty(it), r, numba.boolean, numba.boolean),
        K.limit_begin: (lim, ty(wor), ty(it), r, numba.boolean),
        K.limit_colour: (
            lim,
            ty(wor),
            ty(it),
            r,
            numba.int64,
            numba.int64,
            numba.boolean,
            numba.boolean,
        ),
        K.limit_attach: (lim, ty(wor), ty(it), r, numba.boolean),
        K.limit_end: (lim, ty(wor), ty(it), r, numba.boolean, numba.boolean),
        K.copy_back: (ty(it),),
        K.vbd_start: (ty(wor), ty(it), numba.int64),
        K.vbd_guess: (ty(top), ty(wor), ty(it), r, r),
        K.vbd_colour: (ty(top), ty(wor), ty(it), numba.int64, numba.int64, r, r),
        K.vbd_accelerate: (ty(wor), ty(it), r, numba.boolean),
        K.vbd_residual: (ty(wor), ty(it), numba.float64[::1]),
        K.vbd_finish: (ty(wor), ty(it), r, r, numba.int64),
        K.place: (
            ty(it),
            numba.int32[::1],
            numba.from_dtype(real)[:, :, ::1],
            numba.from_dtype(real)[:, :, ::1],
            numba.int32[::1],
            numba.boolean,
        ),
        K.place_pairs: (
            ty(it),
            numba.int32[::1],
            numba.int32[::1],
            numba.from_dtype(real)[:, ::1],
            numba.from_dtype(real)[:, ::1],
        ),
        K.stop_pairs: (ty(it), numba.int32[::1], numba.int32[::1]),
        K.mean_pair_distance: (
            ty(x),
            numba.int32[::1],
            ty(x),
            numba.int32[::1],
            numba.float64[::1],
        ),
        K.nearest_free: (
            ty(it),
            ty(wor),
            numba.int32[::1],
            numba.from_dtype(real)[:, ::1],
            numba.int32[::1],
            numba.from_dtype(real)[:, ::1],
        ),
        K.gather_points: (
            ty(it),
            numba.int32[::1],
            numba.from_dtype(real)[:, :, ::1],
            numba.float32[:, ::1],
        ),
        K.restart: (ty(it), numba.int32[::1]),
        K.frames_in_blocks: (ty(top), ty(wor), ty(it), numba.int32[::1], lim, run, out),
        K.frames_on_grid: (ty(top), ty(wor), ty(it), numba.int32[::1], lim, run, out, out),
    }


class _NoDevice:
    """What numba-cuda asks of the current device when it compiles an overloaded device function
    (the cooperative grid's ``this_grid`` and ``sync``): its compute capability. There is no
    device here; compile_ptx is told sm_90 anyway."""

    compute_capability = SM90


@pytest.fixture
def no_device(monkeypatch):
    monkeypatch.setattr(numba.cuda.dispatcher, "get_current_device", _NoDevice)


@pytest.mark.parametrize("real", [np.float32, np.float64], ids=["float32", "float64"])
def test_every_kernel_compiles_to_ptx(real, no_device):
    compiled = []
    for kernel, sig in signatures(real).items():
        ptx, _ = cuda.compile_ptx(kernel.py_func, sig, cc=SM90)
        assert ".target sm_90" in ptx and ".entry" in ptx
        if kernel is K.frames_on_grid:  # the grid's synchronisation is CUDA's own
            assert "cudaCGSynchronize" in ptx
        compiled.append(kernel.py_func.__name__)
    # every kernel the module defines is checked
    kernels = {
        name
        for name, obj in vars(K).items()
        if type(obj).__name__ == "CUDADispatcher" and not obj.targetoptions["device"]
    }
    assert kernels == set(compiled)
