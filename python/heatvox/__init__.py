"""heatvox: heat-method distance fields on volumetric grids, from Python.

A thin layer over libheatvox (ctypes and NumPy only) that computes what the
``heatvox`` command does, on arrays:

- ``read_mesh(path) -> (vertices, faces)`` and ``mesh_report(...)``;
- ``read_points(path) -> (points, normals)`` and ``points_surface(points,
  normals, res=...) -> (vertices, faces, report)``: point clouds, with
  normals or without, and the closed surface through them;
- ``sdf(vertices, faces, res=128, ...) -> Grid``: the signed distance of a
  (broken) triangle mesh, bit for bit the command's ``--npy`` output;
- ``distance(sources, solid, voxel_size, ...) -> Grid``: geodesic distance
  around obstacles; ``mask_from_mesh`` marks a mesh's cells as solid;
- ``extend(phi, fields, voxel_size, ...)`` and ``Extender``: extension of
  scalar and vector fields off a level set;
- ``Solver``: the backward-Euler heat step ``(I - t Laplacian) u = f`` and
  Neumann Poisson solves, planned once and reusable;
- ``Grid``: values (NumPy, shaped (nz, ny, nx), x fastest) with origin and
  voxel size; ``write_vdb``, ``write_npy``, ``to_mesh``, ``world_to_index``.

Grids are cell-centred: sample (i, j, k) sits at
``origin + (i + 1/2, j + 1/2, k + 1/2) * voxel_size``, ``origin`` being the
lower corner of the voxel block; ``values[k, j, i]`` is that sample.

Library errors raise :class:`Error` (with ``status``, ``name`` and the
library's ``message``, which names files); bad Python arguments raise
TypeError or ValueError before any C call. Long calls take
``progress=callable(fraction, stage)``; a true return value cancels them.

The library is found through $HEATVOX_LIBRARY, else the copy that ``pip
install`` put in the package (heatvox/libheatvox.so.0), else the path
``make install`` recorded, else the in-tree build (build/libheatvox.so), else
libheatvox.so.0 through the dynamic loader; ``heatvox.library_path`` says
which was loaded. Unless GOMP_SPINCOUNT or OMP_WAIT_POLICY is set, importing
heatvox sets GOMP_SPINCOUNT=1000 (as the command does: libgomp's spinning
slows solves down on busy machines).
"""

from ._lib import Error, Status, fn as _fn, path as library_path
from ._grid import Grid
from ._mesh import mesh_report, read_mesh
from ._points import points_surface, read_points
from ._sdf import sdf, sdf_vdb
from ._heat import Distance, Extender, distance, extend, mask_from_mesh
from ._solve import SolveInfo, Solver

__version__ = _fn.hv_version().decode()

# Public names show as heatvox.X in help() and tracebacks.
for _obj in (Error, Status, Grid, sdf, read_mesh, mesh_report, read_points, points_surface,
             distance, Distance, extend, mask_from_mesh, Extender, Solver, SolveInfo):
    _obj.__module__ = __name__
del _obj


def set_threads(n):
    """Worker threads of the library's CPU kernels (process-wide); 0 restores
    the default (every core)."""
    from ._arrays import integer

    _fn.hv_set_threads(integer(n, "n", 0, 1024))


def get_threads():
    """Worker threads the library's CPU kernels use."""
    return _fn.hv_get_threads()


__all__ = [
    "Error",
    "Extender",
    "Grid",
    "SolveInfo",
    "Solver",
    "Status",
    "distance",
    "Distance",
    "extend",
    "get_threads",
    "library_path",
    "mask_from_mesh",
    "mesh_report",
    "read_mesh",
    "sdf",
    "sdf_vdb",
    "set_threads",
    "__version__",
]
