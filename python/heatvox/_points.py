"""Point clouds: reading them, and the closed surface through them."""

import ctypes

import numpy as np

from . import _arrays
from ._lib import fn, fspath, hv_mesh, hv_points, hv_points_report, struct_dict
from ._mesh import _mesh_arrays


def is_points_file(path):
    """True when path names a point cloud as ``heatvox sdf`` takes one: a text file by its extension (.xyz, .pts, .xyzn) or a PLY file whose
    header declares vertices and no faces."""
    return bool(fn.hv_points_file(fspath(path)))


def read_points(path):
    """Reads a point cloud: text (``x y z nx ny nz`` or ``x y z`` per line,
    ``#`` comments, further columns ignored) or PLY vertices, with ``nx ny
    nz`` or without.

    Returns ``(points, normals)``: float64 arrays (n, 3), the normals of unit
    length, or None for a cloud without them. Raises heatvox.Error naming the
    file and line (or point) when it is unreadable, mixes points with and
    without normals, has NaN or Inf values, or a normal of zero length.
    """
    ptr = ctypes.POINTER(hv_points)()
    fn.hv_points_read(fspath(path), ctypes.byref(ptr))
    try:
        p = ptr.contents
        n = p.count
        pts = np.ctypeslib.as_array(p.xyz, shape=(n, 3)).copy()
        nrm = np.ctypeslib.as_array(p.normals, shape=(n, 3)).copy() if p.normals else None
    finally:
        fn.hv_points_destroy(ctypes.byref(ptr))
    return pts, nrm


def _c_points(points, normals):
    pts = _arrays.c_array(np.asarray(points), np.float64, "points")
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise ValueError("points must have shape (n, 3) with n > 0, got %r" % (pts.shape,))
    nrm = None
    if normals is not None:
        nrm = _arrays.c_array(np.asarray(normals), np.float64, "normals")
        if nrm.shape != pts.shape:
            raise ValueError("normals must have the points' shape %r, got %r" % (pts.shape, nrm.shape))
    ptr = ctypes.POINTER(hv_points)()
    fn.hv_points_from_arrays(ctypes.byref(ptr), _arrays.address(pts),
                             None if nrm is None else _arrays.address(nrm), pts.shape[0])
    return ptr


def surface_of_points(points, normals, opts):
    """(vertices, faces, report) of the closed surface through points
    (normals None: recovered), with hv_sdf_opts opts (placement, t_scale,
    heat_coarsen, backend, threads, orient)."""
    ptr = _c_points(points, normals)
    mesh = ctypes.POINTER(hv_mesh)()
    rep = hv_points_report()
    try:
        fn.hv_points_surface(ptr, ctypes.byref(opts), ctypes.byref(mesh), ctypes.byref(rep))
    finally:
        fn.hv_points_destroy(ctypes.byref(ptr))
    v, f = _mesh_arrays(mesh)
    report = struct_dict(rep)
    return v, f, report


def points_surface(points, normals=None, res=128, pad=4, voxel_size=None, bbox=None, *,
                   t_scale=1.0, heat_coarsen=0, backend="auto", threads=0, orient="auto"):
    """The closed surface through a point cloud, as ``heatvox sdf`` finds it
    for a cloud: the signed heat method with the points' normals (normals
    flipped on part of the cloud are outvoted), its zero set as a mesh, the
    vertices moved onto the points.

    ``points_surface(points, normals, ...)`` with float (n, 3) arrays
    (``normals=None``: a cloud without normals), or ``points_surface(path,
    ...)``. ``orient``: ``"auto"`` recovers the normals from the points
    alone when there are none and uses them when there are, ``"given"``
    needs them, ``"recover"`` ignores them. Placement (``res``, ``pad``,
    ``voxel_size``, ``bbox``), ``t_scale``, ``heat_coarsen``, ``backend``
    and ``threads`` are sdf()'s; by default the heat method's grid is kept
    under 2^22 cells (at most 4 times coarser).

    Returns ``(vertices, faces, report)``: a closed, outward mesh (float64
    (n, 3), uint32 (m, 3)) that sdf() takes, and a dict of
    hv_points_report (points, spacing, normals turned, seconds per stage).
    """
    from ._sdf import _opts  # sdf's option checks

    if isinstance(points, (str, bytes)) or hasattr(points, "__fspath__"):
        points, normals = read_points(points)
    o, _ = _opts(res, pad, voxel_size, bbox, None, False, backend, False, t_scale, heat_coarsen,
                 "auto", True, False, threads, {"orient": orient})
    return surface_of_points(points, normals, o)
