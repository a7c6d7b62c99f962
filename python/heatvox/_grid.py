"""heatvox.Grid: a cell-centred grid of float32 values with its placement."""

import ctypes
import os

import numpy as np

from . import _arrays
from ._lib import fn, fspath, hv_grid, hv_mesh


class Grid:
    """A regular, cell-centred grid of float32 values and where it sits.

    Sample ``(i, j, k)`` sits at ``origin + (i + 1/2, j + 1/2, k + 1/2) * voxel_size``,
    where ``origin`` is the lower corner of the voxel block. ``values`` is a
    NumPy array shaped ``(nz, ny, nx)`` (3D) or ``(ny, nx)`` (2D), x fastest,
    so ``values[k, j, i]`` is sample ``(i, j, k)``.

    Grids returned by heatvox (``sdf``, ``distance``) own the library's
    buffer: ``values`` is a view of it (no copy), and every such view keeps
    the grid alive. ``Grid(values, voxel_size, origin)`` wraps an array of
    your own instead (float32 and C-contiguous are used as they are; other
    arrays are converted once), e.g. to write it as a .vdb or extract a mesh.

    Attributes: ``values``, ``solid`` (bool mask of obstacle cells, or None),
    ``origin`` (tuple of ``dim`` floats), ``voxel_size``, ``shape``, ``dim``,
    ``levelset`` (True for signed distance fields: ``write_vdb`` writes a
    level set), ``band`` (the level set's half width in voxels for
    ``write_vdb``), ``name`` (the default grid name in a .vdb) and ``stats``
    (a dict of the computation's statistics, or None).
    """

    def __init__(self, values, voxel_size, origin=None, solid=None, *, levelset=False, band=3.0, name="values"):
        h = _arrays.positive(voxel_size, "voxel_size")
        arr = np.asarray(values)
        if arr.ndim not in (2, 3):
            raise ValueError("values must have shape (nz, ny, nx) or (ny, nx), got %r" % (arr.shape,))
        dim, n = _arrays.grid_shape(arr.shape, "values.shape")
        arr = _arrays.c_array(arr, np.float32, "values")
        org = _origin(origin, dim, h)
        # An hv_grid struct in Python memory over the NumPy buffer, never given to
        # hv_grid_destroy. grid.h allocates its values 64-byte aligned, but no
        # code reading a grid needs that: the vector kernels use unaligned loads
        # (_mm512_loadu_ps in src/solve/mg/mg_fused.c), the solvers copy right-hand
        # sides into their own (aligned) arrays and FFTW plans on its own
        # buffers. So NumPy's alignment will do and nothing is copied.
        self._ptr = None
        self._struct = hv_grid(dim, (ctypes.c_int * 3)(*n), h, (ctypes.c_double * 3)(*org))
        self._struct.v = ctypes.cast(_arrays.address(arr), ctypes.POINTER(ctypes.c_float))
        self._values = arr
        self._solid = None
        if solid is not None:
            self._set_solid(_arrays.mask_array(solid, arr.shape))
        self.levelset = bool(levelset)
        self.band = _arrays.positive(band, "band")
        self.name = str(name)
        self.stats = None

    @classmethod
    def _adopt(cls, ptr, *, levelset=False, band=3.0, name="values", stats=None):
        """A Grid owning the library's hv_grid * (freed with the Grid)."""
        self = cls.__new__(cls)
        self._ptr = ptr
        self._struct = None
        self._values = None
        self._solid = None
        self.levelset = levelset
        self.band = band
        self.name = name
        self.stats = stats
        return self

    def _set_solid(self, mask):
        """Points the grid's solid mask at a uint8 array kept by the Grid (no copy)."""
        self._solid = mask
        self._c.contents.solid = ctypes.cast(_arrays.address(mask), ctypes.POINTER(ctypes.c_uint8))

    def __del__(self):
        ptr = getattr(self, "_ptr", None)
        if ptr:
            if self._solid is not None:
                ptr.contents.solid = None  # borrowed from Python: not the library's to free
            fn.hv_grid_destroy(ctypes.byref(ptr))

    @property
    def _c(self):
        """The hv_grid * to pass to C."""
        if self._ptr is not None:
            return self._ptr
        return ctypes.pointer(self._struct)

    @property
    def _g(self):
        return self._ptr.contents if self._ptr is not None else self._struct

    @property
    def dim(self):
        """2 or 3."""
        return self._g.dim

    @property
    def shape(self):
        """(nz, ny, nx) in 3D, (ny, nx) in 2D: the shape of ``values``."""
        g = self._g
        return (g.n[2], g.n[1], g.n[0]) if g.dim == 3 else (g.n[1], g.n[0])

    @property
    def voxel_size(self):
        """The voxel size h (world units)."""
        return self._g.h

    @property
    def origin(self):
        """World position of the block's lower corner, (x, y, z) or (x, y) in 2D."""
        return tuple(self._g.origin[: self.dim])

    @property
    def values(self):
        """The float32 values, shaped like ``shape`` (x fastest). For grids the
        library allocated, a view of its buffer (no copy) that keeps this grid
        alive; writes go to the grid."""
        if self._values is not None:
            return self._values
        addr = ctypes.cast(self._ptr.contents.v, ctypes.c_void_p).value
        return _arrays.view(self, addr, self.shape, np.float32)

    @property
    def solid(self):
        """Bool mask of solid (obstacle) cells shaped like ``values``, or None."""
        if self._solid is not None:
            return self._solid.view(np.bool_)
        p = self._g.solid
        if not p:
            return None
        return _arrays.view(self, ctypes.cast(p, ctypes.c_void_p).value, self.shape, np.bool_)

    def __repr__(self):
        return "<heatvox.Grid %s h=%g origin=%s%s%s>" % (
            "x".join(str(s) for s in reversed(self.shape)),
            self.voxel_size,
            tuple(round(o, 9) for o in self.origin),
            " levelset" if self.levelset else "",
            " solid" if self.solid is not None else "",
        )

    # ---- coordinates ----

    def world_to_index(self, points):
        """Fractional grid index of world points.

        ``points``: array (..., 3) of x, y, z (2D grids: (..., 2)). Returns a
        float64 array of the same shape holding ``(i, j, k)`` in x, y, z order
        (NOT the (k, j, i) order of ``values``' axes): integer values are cell
        centres, ``(p - origin) / voxel_size - 1/2``. To sample the nearest
        cell: ``ijk = np.rint(grid.world_to_index(p)).astype(int)`` then
        ``grid.values[ijk[..., 2], ijk[..., 1], ijk[..., 0]]``.
        """
        p = np.asarray(points, dtype=np.float64)
        if p.ndim == 0 or p.shape[-1] != self.dim:
            raise ValueError("points must have shape (..., %d), got %r" % (self.dim, p.shape))
        return (p - np.asarray(self.origin)) / self.voxel_size - 0.5

    def index_to_world(self, index):
        """World position of fractional indices (i, j, k) (x, y, z order); the
        inverse of ``world_to_index``."""
        q = np.asarray(index, dtype=np.float64)
        if q.ndim == 0 or q.shape[-1] != self.dim:
            raise ValueError("index must have shape (..., %d), got %r" % (self.dim, q.shape))
        return np.asarray(self.origin) + (q + 0.5) * self.voxel_size

    # ---- output ----

    def write_npy(self, path):
        """Writes the values as a float32 .npy file, shape (nz, ny, nx) (2D:
        (ny, nx)), through a temporary file renamed into place when complete.
        Raises heatvox.Error naming the file when it cannot be written."""
        fn.hv_write_npy(fspath(path), self._c)

    def write_vdb(self, path, name=None, band=None, dense=False, *, levelset=None, mask_name="obstacles", metadata=None,
                  fog=None):
        """Writes the grid to an OpenVDB file (Blosc compressed), as the command does.

        A signed distance (``levelset`` True, the default for ``sdf`` results
        that are not unsigned) becomes a float grid of class level set:
        negative inside, a narrow band of ``band`` voxels each side (default
        the grid's ``band``, which ``sdf`` sets; 3 unless given) whose
        inactive voxels hold -band*h inside and +band*h outside, or every
        voxel active with ``dense=True``. Other grids (unsigned distances,
        geodesic distances, your own arrays) become dense float grids of
        class unknown; ``band`` and ``dense`` do not apply to them.

        ``name``: the grid's name (default the grid's ``name``: "sdf",
        "distance", ...). A grid with a solid mask also gets a bool grid
        ``mask_name`` (default "obstacles"; None leaves it out).
        ``metadata``: a dict of file metadata strings. The file carries
        "heatvox_version" and the writer's "creator".
        ``fog``: for a level set, the name of a second grid (e.g. "density",
        which Blender's volumes and renderers shade by default) holding its
        inside as a fog volume: 1 inside, 0 outside, a ramp one voxel wide
        across the surface; the inside active.
        Raises heatvox.Error naming the file when it cannot be written.
        """
        name = self.name if name is None else str(name)
        levelset = self.levelset if levelset is None else bool(levelset)
        band = self.band if band is None else _arrays.positive(band, "band")
        if not name:
            raise ValueError("name must not be empty")
        if fog is not None and (not levelset or not str(fog) or str(fog) == name):
            raise ValueError("fog names a second grid of a level set, not %r, got %r" % (name, fog))
        w = ctypes.c_void_p()
        fn.hv_vdb_writer_create(ctypes.byref(w))
        try:
            if levelset:
                fn.hv_vdb_writer_add_levelset(w, self._c, name.encode(), band, 1 if dense else 0)
            else:
                fn.hv_vdb_writer_add_float(w, self._c, name.encode())
            if fog is not None:
                fn.hv_vdb_writer_add_fog(w, self._c, str(fog).encode())
            if mask_name is not None and self._g.solid:
                fn.hv_vdb_writer_add_mask(w, self._c, str(mask_name).encode())
            fn.hv_vdb_writer_set_meta(w, b"heatvox_version", fn.hv_version())
            for k, v in (metadata or {}).items():
                fn.hv_vdb_writer_set_meta(w, str(k).encode(), str(v).encode())
            fn.hv_vdb_writer_write(w, fspath(path))
        finally:
            fn.hv_vdb_writer_destroy(ctypes.byref(w))

    def to_mesh(self, adaptivity=0.0, isovalue=0.0):
        """The isosurface ``values == isovalue`` of a 3D grid as a closed,
        manifold, consistently oriented triangle mesh (outward normals for a
        signed distance, negative inside), by OpenVDB's volumeToMesh with its
        quads split into triangles; cells outside the block count as outside.

        ``adaptivity`` in [0, 1]: 0 keeps one vertex per crossed voxel, larger
        values merge flat regions into fewer triangles.
        Returns ``(vertices, faces)``, float64 (n, 3) world coordinates and
        uint32 (m, 3). Raises heatvox.Error when no cell crosses ``isovalue``.
        """
        if self.dim != 3:
            raise ValueError("to_mesh needs a 3D grid")
        a = _arrays.real(adaptivity, "adaptivity", 0.0)
        if a > 1:
            raise ValueError("adaptivity must be in [0, 1], got %r" % (adaptivity,))
        iso = _arrays.real(isovalue, "isovalue")
        if not np.isfinite(iso):
            raise ValueError("isovalue must be finite, got %r" % (isovalue,))
        from ._mesh import _mesh_arrays

        ptr = ctypes.POINTER(hv_mesh)()
        fn.hv_grid_to_mesh(self._c, iso, a, ctypes.byref(ptr))
        return _mesh_arrays(ptr)


def _origin(origin, dim, h):
    """Three origin coordinates from None (0) or dim (or 3) numbers. A 2D grid
    without a z gets -h/2, so that its one layer of cells is centred on z = 0
    (as `heatvox distance --dim 2` places it)."""
    if origin is None:
        return [0.0, 0.0, -0.5 * h if dim == 2 else 0.0]
    o = np.asarray(origin, dtype=np.float64).ravel()
    if o.size not in (dim, 3) or not np.all(np.isfinite(o)):
        raise ValueError("origin must be %d finite numbers, got %r" % (dim, origin))
    o = list(o)
    if len(o) == 2:
        o.append(-0.5 * h)
    return o


def new_grid(shape, voxel_size, origin=None):
    """A zeroed library-owned hv_grid * of `shape` ((nz, ny, nx) or (ny, nx))."""
    dim, n = _arrays.grid_shape(shape)
    h = _arrays.positive(voxel_size, "voxel_size")
    org = _origin(origin, dim, h)
    ptr = ctypes.POINTER(hv_grid)()
    fn.hv_grid_create(ctypes.byref(ptr), dim, (ctypes.c_int * 3)(*n), h, (ctypes.c_double * 3)(*org))
    return ptr


def is_path(x):
    return isinstance(x, (str, bytes, os.PathLike))
