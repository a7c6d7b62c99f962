"""Triangle meshes: reading files, defect reports, meshes handed to C."""

import ctypes
import os

import numpy as np

from . import _arrays
from ._lib import fn, fspath, hv_mesh, hv_mesh_report, struct_dict


class _MeshOwner:
    """Owns an hv_mesh * and frees it when the arrays viewing it are gone."""

    def __init__(self, ptr):
        self.ptr = ptr

    def __del__(self):
        if self.ptr:
            fn.hv_mesh_destroy(ctypes.byref(self.ptr))


def _mesh_arrays(ptr):
    """(vertices, faces) viewing an hv_mesh's own arrays (no copy); the mesh is
    freed when both arrays are."""
    m = ptr.contents
    owner = _MeshOwner(ptr)
    verts = _arrays.view(owner, ctypes.cast(m.verts, ctypes.c_void_p).value, (m.nverts, 3), np.float64)
    faces = _arrays.view(owner, ctypes.cast(m.tris, ctypes.c_void_p).value, (m.ntris, 3), np.uint32)
    return verts, faces


def read_mesh(path):
    """Reads a triangle mesh: OBJ, PLY (ascii, binary little and big endian),
    STL (ascii, binary) or OFF, by extension, else by content; or, by
    extension, glTF 2.0 (.gltf, .glb), FBX, 3MF, COLLADA (.dae) or DirectX
    (.x) through assimp, the scene graph flattened with its transforms.

    As the command's readers do, polygons are fanned into triangles, vertices
    at exactly the same position are welded and vertices no face uses are
    dropped.

    Returns ``(vertices, faces)``: float64 array (n, 3) of coordinates and
    uint32 array (m, 3) of vertex indices (the library's own arrays, no copy).
    Raises heatvox.Error naming the file (and line or byte offset) when it is
    missing, unreadable or malformed.
    """
    ptr = ctypes.POINTER(hv_mesh)()
    fn.hv_mesh_read(fspath(path), ctypes.byref(ptr))
    return _mesh_arrays(ptr)


def check_mesh(vertices, faces):
    """(vertices, faces) as the C-contiguous float64 (n, 3) and uint32 (m, 3)
    arrays hv_mesh_from_arrays reads; no copy when they already are."""
    if isinstance(vertices, (str, bytes, os.PathLike)):
        raise TypeError("vertices is a path: read it with heatvox.read_mesh first, or pass faces=None")
    v = np.asarray(vertices)
    f = np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
        raise ValueError("vertices must have shape (n, 3) with n > 0, got %r" % (v.shape,))
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
        raise ValueError("faces must have shape (m, 3) with m > 0, got %r" % (f.shape,))
    if not np.issubdtype(f.dtype, np.integer):
        raise TypeError("faces must be an integer array, got dtype %s" % f.dtype)
    if f.dtype != np.uint32:
        lo, hi = int(f.min()), int(f.max())
        if lo < 0:
            raise ValueError("faces: vertex index %d is negative" % lo)
        if hi >= v.shape[0]:
            raise ValueError("faces: vertex index %d, but there are %d vertices" % (hi, v.shape[0]))
    elif int(f.max()) >= v.shape[0]:
        raise ValueError("faces: vertex index %d, but there are %d vertices" % (int(f.max()), v.shape[0]))
    v = _arrays.c_array(v, np.float64, "vertices")
    f = _arrays.c_array(f, np.uint32, "faces")
    return v, f


class c_mesh:
    """An hv_mesh built from arrays for the length of a with block.

    hv_mesh_from_arrays copies the arrays (the library keeps its own welded
    mesh, as hv_mesh_read would build it); the mesh is freed at the end."""

    def __init__(self, vertices, faces):
        self.v, self.f = check_mesh(vertices, faces)
        self.ptr = ctypes.POINTER(hv_mesh)()

    def __enter__(self):
        fn.hv_mesh_from_arrays(
            ctypes.byref(self.ptr),
            _arrays.address(self.v),
            self.v.shape[0],
            _arrays.address(self.f),
            self.f.shape[0],
        )
        return self.ptr

    def __exit__(self, *exc):
        fn.hv_mesh_destroy(ctypes.byref(self.ptr))
        return False


def mesh_report(vertices, faces=None):
    """The defect report of a mesh (hv_mesh_report, as ``heatvox info`` prints it).

    ``mesh_report(vertices, faces)`` reports on arrays (welded by exact
    position first, as the readers do); ``mesh_report(path)`` reads the file,
    and then also reports what the reader did (``input_vertices``,
    ``unreferenced_vertices``, ``polygons_fanned``, 0 for arrays).

    Returns a dict with every field of hv_mesh_report: vertices, triangles,
    polygons_fanned, boundary_edges, nonmanifold_edges, inconsistent_edges,
    duplicate_faces, degenerate_faces, nonfinite_vertices, components, edges,
    vertex_components, input_vertices, unreferenced_vertices, signed_volume
    (> 0 for a closed, outward-oriented mesh).
    """
    r = hv_mesh_report()
    if faces is None:
        if not isinstance(vertices, (str, bytes, os.PathLike)):
            raise TypeError("mesh_report needs (vertices, faces) or a path")
        ptr = ctypes.POINTER(hv_mesh)()
        fn.hv_mesh_read(fspath(vertices), ctypes.byref(ptr))
        try:
            fn.hv_mesh_report_compute(ptr, ctypes.byref(r))
        finally:
            fn.hv_mesh_destroy(ctypes.byref(ptr))
    else:
        with c_mesh(vertices, faces) as ptr:
            fn.hv_mesh_report_compute(ptr, ctypes.byref(r))
    return struct_dict(r)
