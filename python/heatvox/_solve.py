"""heatvox.Solver: (alpha I - beta Laplacian) u = f on a cell-centred grid (solve.h)."""

import ctypes
from dataclasses import dataclass, field
from typing import List

import numpy as np

from . import _arrays
from ._lib import (
    backend_code,
    backend_name,
    coarse_code,
    fn,
    fspath,
    hv_problem,
    hv_solve_info,
    hv_solver_opts,
)

_SMOOTHERS = {"rbgs": 0, "jacobi": 1, "chebyshev": 2, "auto": 3}



@dataclass
class SolveInfo:
    """How a solve went (hv_solve_info): ``backend`` that ran, ``reason`` it
    stopped ("converged", "max-iterations", "stagnated", "exact"),
    ``iterations`` (outer: corrections or CG iterations), ``cycles``
    (V-cycles; 0 when not counted), ``relres`` (final relative residual
    ||f - A u|| / ||f||, double precision), ``history`` (relres after each
    iteration, the initial one first), ``seconds``. ``converged`` is True
    for "converged" and "exact"; not converging is information, not an
    error."""

    backend: str
    reason: str
    iterations: int
    cycles: int
    relres: float
    history: List[float] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def converged(self):
        return self.reason in ("converged", "exact")


class Solver:
    """Solves ``(alpha I - beta Laplacian) u = f`` with homogeneous Neumann
    walls and optional solid cells (no flux through them; u = 0 there): the
    backward-Euler heat step (alpha = 1, beta = t) and the Neumann Poisson
    equation (alpha = 0, beta = 1: ``-Laplacian u = f``; f is projected onto
    the range, mean-free per connected fluid region, and the mean-free u is
    returned).

    Planning (multigrid hierarchy, FFTW plans) happens once in the
    constructor; ``solve`` is then cheap and repeatable. Not thread-safe:
    one Solver per thread.

    ``Solver(shape, voxel_size, alpha=1.0, beta=1.0, solid=None,
    backend="auto", tol=1e-6, max_iter=50, smoother="auto", pre_smooth=2,
    post_smooth=2, nonzero_guess=False, fftw_double=True,
    fftw_measure=False, wisdom_file=None, cycles_per_iteration=0,
    coarse="auto")``:
    ``shape`` (nz, ny, nx) or (ny, nx); the options are hv_solver_opts'
    (solve.h); ``backend`` "auto" (FFTW on plain boxes, multigrid with solid
    cells, an OpenCL GPU for large grids), "mg", "fftw", "opencl";
    ``nonzero_guess=True`` makes ``solve(f, out=u)`` start from u;
    ``coarse`` "auto", "geometric" or "aggregation" picks mg's coarse
    levels with solid cells (aggregation keeps thin walls). See also
    ``Solver.heat`` and ``Solver.poisson``. ``info`` holds the last solve's
    :class:`SolveInfo`.
    """

    def __init__(
        self,
        shape,
        voxel_size,
        alpha=1.0,
        beta=1.0,
        solid=None,
        *,
        backend="auto",
        tol=1e-6,
        max_iter=50,
        smoother="auto",
        pre_smooth=2,
        post_smooth=2,
        nonzero_guess=False,
        fftw_double=True,
        fftw_measure=False,
        wisdom_file=None,
        cycles_per_iteration=0,
        coarse="auto",
    ):
        self._s = ctypes.c_void_p()
        dim, n = _arrays.grid_shape(shape)
        self.shape = tuple(int(s) for s in shape)
        self.voxel_size = _arrays.positive(voxel_size, "voxel_size")
        mask = _arrays.mask_array(solid, self.shape) if solid is not None else None
        p = hv_problem(dim, (ctypes.c_int * 3)(*n), self.voxel_size)
        if mask is not None:
            p.solid = ctypes.cast(_arrays.address(mask), ctypes.POINTER(ctypes.c_uint8))  # copied at create
        p.alpha = _arrays.real(alpha, "alpha", 0.0)
        p.beta = _arrays.positive(beta, "beta")
        o = hv_solver_opts()
        fn.hv_solver_opts_default(ctypes.byref(o))
        o.backend = backend_code(backend)
        if smoother not in _SMOOTHERS:
            raise ValueError("smoother must be one of %s, got %r" % (", ".join(_SMOOTHERS), smoother))
        o.smoother = _SMOOTHERS[smoother]
        o.coarse = coarse_code(coarse)
        o.tol = _arrays.positive(tol, "tol")
        o.max_iter = _arrays.integer(max_iter, "max_iter", 1)
        o.pre_smooth = _arrays.integer(pre_smooth, "pre_smooth", 0)
        o.post_smooth = _arrays.integer(post_smooth, "post_smooth", 0)
        o.nonzero_guess = 1 if nonzero_guess else 0
        o.fftw_double = 1 if fftw_double else 0
        o.fftw_measure = 1 if fftw_measure else 0
        o.cycles_per_iteration = _arrays.integer(cycles_per_iteration, "cycles_per_iteration", 0, 8)
        if wisdom_file is not None:
            self._wisdom = fspath(wisdom_file)  # the solver keeps the pointer
            o.wisdom_file = self._wisdom
        self.alpha, self.beta, self.nonzero_guess = p.alpha, p.beta, bool(nonzero_guess)
        fn.hv_solver_create(ctypes.byref(self._s), ctypes.byref(p), ctypes.byref(o))
        self.info = None

    @classmethod
    def heat(cls, shape, voxel_size, t, solid=None, **options):
        """A solver for the backward-Euler heat step ``(I - t Laplacian) u = f``."""
        return cls(shape, voxel_size, 1.0, _arrays.positive(t, "t"), solid, **options)

    @classmethod
    def poisson(cls, shape, voxel_size, solid=None, **options):
        """A solver for the Neumann Poisson equation ``-Laplacian u = f``
        (mean-free f and u per connected fluid region)."""
        return cls(shape, voxel_size, 0.0, 1.0, solid, **options)

    @property
    def backend(self):
        """The backend this solver runs ("mg", "fftw", "opencl")."""
        return backend_name(fn.hv_solver_backend(self._s))

    def solve(self, f, out=None):
        """Solves A u = f and returns u (``info`` says how it went).

        ``f``: array of the solver's shape; float32 is solved by
        hv_solver_solve, float64 by hv_solver_solve_d (read in place when
        C-contiguous); other dtypes are converted to float64. ``out``: an
        array for u of f's dtype, C-contiguous (with ``nonzero_guess`` it
        holds the initial guess); by default a new one. Raises heatvox.Error
        (status NUMERIC) when f holds NaN or Inf.
        """
        if not self._s:
            raise ValueError("the solver is closed")
        a = np.asarray(f)
        dtype = np.float32 if a.dtype == np.float32 else np.float64
        a = _arrays.c_array(a, dtype, "f")
        if a.shape != self.shape:
            raise ValueError("f has shape %r, expected %r" % (a.shape, self.shape))
        if out is None:
            # without a guess every backend writes all of u itself
            out = (np.zeros if self.nonzero_guess else np.empty)(self.shape, dtype=dtype)
        elif (
            not isinstance(out, np.ndarray)
            or out.dtype != dtype
            or out.shape != self.shape
            or not out.flags.c_contiguous
            or not out.flags.writeable
        ):
            raise ValueError("out must be a writable C-contiguous %s array of shape %r" % (np.dtype(dtype).name, self.shape))
        info = hv_solve_info()
        solve = fn.hv_solver_solve if dtype == np.float32 else fn.hv_solver_solve_d
        solve(self._s, _arrays.address(a), _arrays.address(out), ctypes.byref(info))
        self.info = SolveInfo(
            backend=backend_name(info.backend),
            reason=fn.hv_stop_reason_str(info.reason).decode(),
            iterations=info.iterations,
            cycles=info.cycles,
            relres=info.relres,
            history=list(info.history[: info.nhistory]),
            seconds=info.seconds,
        )
        return out

    def close(self):
        """Frees the solver (also done when it is garbage collected)."""
        if getattr(self, "_s", None):
            fn.hv_solver_destroy(ctypes.byref(self._s))

    __del__ = close

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False
