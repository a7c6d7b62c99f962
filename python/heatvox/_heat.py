"""Geodesic distance around obstacles and extension off a level set (heat.h)."""

import ctypes
import math

import numpy as np

from . import _arrays
from ._grid import Grid, new_grid
from ._lib import (
    backend_code,
    coarse_code,
    backend_name,
    fn,
    hv_distance_opts,
    hv_distance_sources,
    hv_distance_stats,
    hv_extend_field,
    hv_extend_opts,
    hv_extend_stats,
    progress_scope,
    struct_dict,
)
from ._mesh import c_mesh

_c_float_p = ctypes.POINTER(ctypes.c_float)


def _float_p(a):
    return ctypes.cast(_arrays.address(a), _c_float_p)


def _source_arrays(sources, shape, dim):
    """(voxels int32 (n, 3) or None, points float64 (n, 3) or None) from the
    forms distance() documents."""
    if sources is None:
        return None, None
    s = np.asarray(sources)
    if s.dtype == np.bool_:
        if s.shape != tuple(shape):
            raise ValueError("a boolean sources array must have the grid's shape %r, got %r" % (tuple(shape), s.shape))
        nz = np.nonzero(s)  # axes (k, j, i) or (j, i)
        vox = np.zeros((nz[0].size, 3), dtype=np.int32)
        for a in range(dim):
            vox[:, a] = nz[dim - 1 - a]
        return vox, None
    if s.ndim != 2 or s.shape[1] not in (dim, 3) or s.shape[0] == 0:
        raise ValueError(
            "sources must be a boolean array of the grid's shape, or an array (n, %d) of "
            "points (float) or voxel indices (int); got shape %r" % (dim, s.shape)
        )
    if np.issubdtype(s.dtype, np.integer):
        if s.shape[1] != dim:
            raise ValueError("voxel sources must have shape (n, %d) (i, j%s), got %r" % (dim, ", k" if dim == 3 else "", s.shape))
        size = _arrays.grid_shape(shape)[1]
        for a in range(dim):
            if s[:, a].min() < 0 or s[:, a].max() >= size[a]:
                raise ValueError("voxel sources: index %s out of range 0..%d" % ("ijk"[a], size[a] - 1))
        if s.shape[1] == 3:
            return _arrays.c_array(s, np.int32, "sources"), None
        vox = np.zeros((s.shape[0], 3), dtype=np.int32)
        vox[:, :2] = s
        return vox, None
    if not np.issubdtype(s.dtype, np.floating):
        raise TypeError("sources: expected bool, integer or float array, got dtype %s" % s.dtype)
    if not np.all(np.isfinite(s)):
        raise ValueError("sources: points must be finite")
    if s.shape[1] == 3:
        return None, _arrays.c_array(s, np.float64, "sources")
    pts = np.zeros((s.shape[0], 3), dtype=np.float64)
    pts[:, :2] = s
    return None, pts


def _distance_opts(t_scale, backend, unreachable, solid_value, max_stages, diffuse_tol,
                   poisson_tol, coarse, stages):
    o = hv_distance_opts()
    fn.hv_distance_opts_default(ctypes.byref(o))
    o.t_scale = _arrays.positive(t_scale, "t_scale")
    o.max_stages = _arrays.integer(max_stages, "max_stages", 1)
    o.diffuse_tol = _arrays.positive(diffuse_tol, "diffuse_tol")
    o.poisson_tol = _arrays.positive(poisson_tol, "poisson_tol")
    o.backend = backend_code(backend)
    o.coarse = coarse_code(coarse)
    if stages not in ("tiles", "whole"):
        raise ValueError("stages: expected 'tiles' or 'whole', got %r" % (stages,))
    o.whole_stages = stages == "whole"
    o.unreachable = _arrays.real(unreachable, "unreachable")
    o.solid_value = o.unreachable if solid_value is None else _arrays.real(solid_value, "solid_value")
    return o


def _grid_shape_of(solid, sources, shape):
    if solid is not None:
        grid_shape = np.shape(solid)
    elif sources is not None and np.asarray(sources).dtype == np.bool_:
        grid_shape = np.shape(sources)
    elif shape is not None:
        grid_shape = tuple(shape)
    else:
        raise ValueError("distance needs the grid's shape: from solid, a boolean sources array, or shape=")
    if shape is not None and tuple(shape) != tuple(grid_shape):
        raise ValueError("shape=%r differs from the arrays' shape %r" % (tuple(shape), tuple(grid_shape)))
    return tuple(grid_shape)


class Distance:
    """Geodesic distance queries on one set of obstacles (hv_distance): the
    obstacle mask, the Poisson solver and its coarse levels are made once, at
    construction, so that every :meth:`query` with new sources pays no set-up.

    ``Distance(solid=None, voxel_size=1.0, shape=None, origin=None, **options)``
    takes the grid and the options of :func:`distance` (``t_scale``,
    ``backend``, ``unreachable``, ``solid_value``, ``max_stages``,
    ``diffuse_tol``, ``poisson_tol``, ``coarse``, ``stages``). ``query(sources,
    mesh=None, progress=None)`` returns a :class:`Grid` as :func:`distance`
    does; its ``stats["t_setup"]`` is the set-up's time on the first query and
    0 after. ``close()`` (or ``with``) releases the solvers.
    """

    def __init__(self, solid=None, voxel_size=1.0, *, shape=None, origin=None, t_scale=2.0,
                 backend="auto", unreachable=math.inf, solid_value=None, max_stages=1000,
                 diffuse_tol=1e-11, poisson_tol=1e-9, coarse="auto", stages="tiles"):
        if solid is None and shape is None:
            raise ValueError("Distance needs the grid's shape: from solid, or shape=")
        self.shape = _grid_shape_of(solid, None, shape)
        self.dim, _ = _arrays.grid_shape(self.shape, "the grid's shape")
        self._voxel_size, self._origin = voxel_size, origin
        self._mask = _arrays.mask_array(solid, self.shape) if solid is not None else None
        self._o = _distance_opts(t_scale, backend, unreachable, solid_value, max_stages,
                                 diffuse_tol, poisson_tol, coarse, stages)
        g = self._grid()
        self._c = ctypes.c_void_p()
        fn.hv_distance_create(ctypes.byref(self._c), g._c, ctypes.byref(self._o))

    def _grid(self):
        g = Grid._adopt(new_grid(self.shape, self._voxel_size, self._origin), name="distance")
        if self._mask is not None:
            g._set_solid(self._mask)
        return g

    def query(self, sources, mesh=None, progress=None):
        """The distance from ``sources`` (and ``mesh``), as :func:`distance`."""
        if not self._c:
            raise ValueError("query on a closed Distance")
        voxels, points = _source_arrays(sources, self.shape, self.dim)
        if voxels is None and points is None and mesh is None:
            raise ValueError("no sources: give sources and/or mesh")
        if mesh is not None and self.dim != 3:
            raise ValueError("a mesh source needs a 3D grid")
        g = self._grid()
        src = hv_distance_sources()
        if voxels is not None:
            src.voxels = ctypes.cast(_arrays.address(voxels), ctypes.POINTER(ctypes.c_int))
            src.nvoxels = voxels.shape[0]
        if points is not None:
            src.points = ctypes.cast(_arrays.address(points), ctypes.POINTER(ctypes.c_double))
            src.npoints = points.shape[0]
        st = hv_distance_stats()

        def run():
            with progress_scope(progress):
                fn.hv_distance_query(self._c, ctypes.byref(src), g._c, ctypes.byref(st))

        if mesh is not None:
            with c_mesh(*mesh) as m:
                src.mesh = m
                run()
        else:
            run()
        g.stats = struct_dict(st)
        g.stats["backend"] = backend_name(st.backend)
        return g

    def close(self):
        if self._c:
            fn.hv_distance_destroy(ctypes.byref(self._c))
            self._c = ctypes.c_void_p()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def distance(
    sources,
    solid=None,
    voxel_size=1.0,
    *,
    shape=None,
    origin=None,
    mesh=None,
    t_scale=2.0,
    backend="auto",
    unreachable=math.inf,
    solid_value=None,
    max_stages=1000,
    diffuse_tol=1e-11,
    poisson_tol=1e-9,
    progress=None,
    coarse="auto",
    stages="tiles",
):
    """Geodesic distance from sources through free space, around obstacles,
    by the heat method: what ``heatvox distance`` computes, on arrays a
    simulation already has. For many queries on the same obstacles, use
    :class:`Distance`, which pays the set-up once.

    The grid: ``solid``'s shape, else a boolean ``sources``' shape, else
    ``shape``; (nz, ny, nx) for 3D, (ny, nx) for 2D. ``voxel_size`` and
    ``origin`` (the block's lower corner, default 0) place it in the world:
    sample (i, j, k) sits at origin + (i + 1/2) * voxel_size.

    sources (any of, combined with ``mesh``):
      - a bool array of the grid's shape: True cells are sources;
      - an int array (n, 3) (2D: (n, 2)) of voxel indices (i, j, k), x first;
      - a float array (n, 3) (2D: (n, 2)) of world points, splatted
        trilinearly onto the fluid cells around them;
      - None, with ``mesh``.
    solid: None or a bool array of the grid's shape, True = obstacle cell.
    mesh: (vertices, faces) whose surface is a source (3D).
    Options (heat.h, hv_distance_opts): ``t_scale`` (t = t_scale h^2,
    default 2), ``backend``, ``unreachable`` (value of fluid cells no source
    reaches, default inf), ``solid_value`` (value of solid cells; default
    ``unreachable``, as the command's ``--unreachable`` sets both),
    ``max_stages``, ``diffuse_tol``, ``poisson_tol``, ``progress``, ``coarse``
    (the solves' coarse levels with obstacles: "auto", "geometric" or
    "aggregation", as :class:`Solver`), ``stages`` ("tiles", the default: each
    stage solves on the tiles near its front; "whole": on the whole grid).

    Returns a :class:`Grid` named "distance" (world units, >= 0; with the
    solid mask when given) with ``stats`` (a dict of hv_distance_stats:
    stages, regions, unreachable_cells, iterations, cells_solved, seconds, ...).
    """
    grid_shape = _grid_shape_of(solid, sources, shape)
    with Distance(solid, voxel_size, shape=grid_shape, origin=origin, t_scale=t_scale,
                  backend=backend, unreachable=unreachable, solid_value=solid_value,
                  max_stages=max_stages, diffuse_tol=diffuse_tol, poisson_tol=poisson_tol,
                  coarse=coarse, stages=stages) as d:
        return d.query(sources, mesh=mesh, progress=progress)


def mask_from_mesh(vertices, faces, shape, voxel_size, origin=None):
    """Solid cells of a 3D grid: every cell whose closed box meets a triangle
    (hv_mask_from_mesh; what ``heatvox distance --obstacle-mesh`` uses). A
    closed mesh gives a watertight shell; its inside stays fluid.

    Returns a bool array of ``shape`` (nz, ny, nx)."""
    dim, _ = _arrays.grid_shape(shape)
    if dim != 3:
        raise ValueError("mask_from_mesh needs a 3D shape (nz, ny, nx)")
    g = Grid._adopt(new_grid(shape, voxel_size, origin))
    with c_mesh(vertices, faces) as m:
        fn.hv_mask_from_mesh(g._c, m, None)
    return g.solid


class Extender:
    """Extension of fields off the zero set of a level set, reusable across
    calls on grids of one shape (hv_extender: solvers are built on first use
    and kept, so a simulation's time steps mostly pay for the solves).

    ``Extender(shape, voxel_size, solid=None, band=1.5, t_scale=0.25,
    closest_point=True, out_band=0.0, background=0.0, max_levels=6,
    backend="auto", tol=1e-10, box_only=False)``; the options are those of
    hv_extend_opts (heat.h) and ``heatvox extend``: cells with
    |phi| < band*h carry the values; t = t_scale h^2; ``closest_point=False``
    is ``--plain``; ``out_band`` > 0 fills only cells with
    |phi| < out_band*h (others get ``background``). Not thread-safe.
    Use ``extend()``; ``stats`` holds the last call's hv_extend_stats.
    """

    def __init__(
        self,
        shape,
        voxel_size,
        solid=None,
        *,
        band=1.5,
        t_scale=0.25,
        closest_point=True,
        out_band=0.0,
        background=0.0,
        max_levels=6,
        backend="auto",
        tol=1e-10,
        box_only=False,
    ):
        self._e = ctypes.c_void_p()
        self.dim, n = _arrays.grid_shape(shape)
        self.shape = tuple(int(s) for s in shape)
        self.voxel_size = _arrays.positive(voxel_size, "voxel_size")
        o = hv_extend_opts()
        fn.hv_extend_opts_default(ctypes.byref(o))
        o.band = _arrays.positive(band, "band")
        o.t_scale = _arrays.positive(t_scale, "t_scale")
        o.closest_point = 1 if closest_point else 0
        o.out_band = _arrays.real(out_band, "out_band", 0.0)
        o.background = _arrays.real(background, "background")
        o.max_levels = _arrays.integer(max_levels, "max_levels", 0)
        o.backend = backend_code(backend)
        o.tol = _arrays.positive(tol, "tol")
        o.box_only = 1 if box_only else 0
        mask = _arrays.mask_array(solid, self.shape) if solid is not None else None
        fn.hv_extender_create(
            ctypes.byref(self._e),
            self.dim,
            (ctypes.c_int * 3)(*n),
            self.voxel_size,
            _arrays.address(mask) if mask is not None else None,  # copied by the library
            ctypes.byref(o),
        )
        self.stats = None

    def close(self):
        """Frees the extender (also done when it is garbage collected)."""
        if getattr(self, "_e", None):
            fn.hv_extender_destroy(ctypes.byref(self._e))

    __del__ = close

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def _field(self, a, name):
        arr = _arrays.c_array(a, np.float32, name)
        if arr.shape != self.shape:
            raise ValueError("%s has shape %r, expected %r" % (name, arr.shape, self.shape))
        return arr

    def extend(self, phi, fields, out=None, progress=None):
        """Extends ``fields`` off the zero set of ``phi``.

        phi: float32 array (nz, ny, nx) (2D: (ny, nx)), negative inside; a
          Grid is accepted too.
        fields: one array of phi's shape (a scalar field); a tuple of 2 or 3
          arrays, or an array (c, nz, ny, nx) with c = 2 or 3 (a vector: its
          magnitude and direction are diffused separately, the vector heat
          method); or a list of those, extended together with one solver.
        out: None (new arrays), or arrays of the same structure to write
          into (they may be the inputs themselves).
        Float32 C-contiguous inputs are read in place; others are converted.
        Returns the extended fields in the structure given (array, tuple,
        (c, ...) array or list). Raises heatvox.Error (e.g. no cell has
        |phi| < band*h), ValueError for shapes.
        """
        if isinstance(phi, Grid):
            phi = phi.values
        phi = self._field(phi, "phi")
        single = not isinstance(fields, list)
        flist = [fields] if single else list(fields)
        olist = [None] * len(flist) if out is None else ([out] if single else list(out))
        if len(olist) != len(flist):
            raise ValueError("out must have the structure of fields")
        if not flist:
            raise ValueError("no fields to extend")
        c_fields = (hv_extend_field * len(flist))()
        keep, results = [], []
        for q, (f, fo) in enumerate(zip(flist, olist)):
            name = "fields[%d]" % q if not single else "fields"
            if isinstance(f, tuple):
                comps = [self._field(c, "%s[%d]" % (name, i)) for i, c in enumerate(f)]
                kind = "tuple"
            else:
                arr = np.asarray(f)
                if arr.shape == self.shape:
                    comps, kind = [self._field(arr, name)], "scalar"
                elif arr.ndim == len(self.shape) + 1 and arr.shape[1:] == self.shape:
                    arr = _arrays.c_array(arr, np.float32, name)
                    comps, kind = [arr[i] for i in range(arr.shape[0])], "stacked"
                else:
                    raise ValueError("%s has shape %r; expected %r, (c,)+%r or a tuple of arrays" % (name, arr.shape, self.shape, self.shape))
            if not 1 <= len(comps) <= 3 or (kind != "scalar" and len(comps) < 2):
                raise ValueError("%s: a vector has 2 or 3 components, got %d" % (name, len(comps)))
            if fo is None:
                if kind == "stacked":
                    ostack = np.empty((len(comps),) + self.shape, dtype=np.float32)
                    outs = [ostack[i] for i in range(len(comps))]
                else:
                    outs = [np.empty(self.shape, dtype=np.float32) for _ in comps]
            else:
                fo_list = [fo] if kind == "scalar" else list(fo)
                if len(fo_list) != len(comps):
                    raise ValueError("out for %s must have %d components" % (name, len(comps)))
                outs = []
                for i, a in enumerate(fo_list):
                    if not isinstance(a, np.ndarray) or a.dtype != np.float32 or not a.flags.c_contiguous or a.shape != self.shape or not a.flags.writeable:
                        raise ValueError("out arrays must be writable C-contiguous float32 arrays of shape %r" % (self.shape,))
                    outs.append(a)
                ostack = fo if kind == "stacked" else None
            c_fields[q].ncomp = len(comps)
            for i in range(len(comps)):
                c_fields[q].in_[i] = _float_p(comps[i])
                c_fields[q].out[i] = _float_p(outs[i])
            keep.append((comps, outs))
            if kind == "scalar":
                results.append(outs[0])
            elif kind == "tuple":
                results.append(tuple(outs))
            else:
                results.append(ostack)
        st = hv_extend_stats()
        with progress_scope(progress):
            fn.hv_extend_many(self._e, _arrays.address(phi), len(flist), c_fields, ctypes.byref(st))
        self.stats = struct_dict(st)
        return results[0] if single else results


def extend(phi, fields, voxel_size=None, band=1.5, *, solid=None, progress=None, **options):
    """Extends scalar and vector fields off the zero set of a level set,
    constant along the normals: what ``heatvox extend`` computes, on arrays.

    ``phi``: float32 (nz, ny, nx) (2D: (ny, nx)) signed distance, negative
    inside, or a Grid (then ``voxel_size`` defaults to its own).
    ``fields``: an array (scalar), a tuple of 2-3 arrays or a (c, ...) array
    (vector), or a list of those. ``band``: cells with |phi| < band*h carry
    the values (default 1.5). Further options: those of :class:`Extender`
    (t_scale, closest_point, out_band, background, max_levels, backend, tol,
    box_only). Returns the extended fields in the structure given.

    A one-shot convenience: for repeated calls on one grid shape (a
    simulation's time steps) keep an :class:`Extender`.
    """
    if isinstance(phi, Grid):
        if voxel_size is None:
            voxel_size = phi.voxel_size
        phi = phi.values
    if voxel_size is None:
        raise TypeError("extend() needs voxel_size (or a Grid as phi)")
    phi = np.asarray(phi)
    if phi.ndim not in (2, 3):
        raise ValueError("phi must have shape (nz, ny, nx) or (ny, nx), got %r" % (phi.shape,))
    with Extender(phi.shape, voxel_size, solid, band=band, **options) as e:
        return e.extend(phi, fields, progress=progress)
