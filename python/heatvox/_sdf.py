"""heatvox.sdf: signed distance volumes of (broken) triangle meshes."""

import ctypes

import numpy as np

from . import _arrays
from ._grid import Grid, is_path
from ._lib import (
    HV_MAX_THREADS,
    HV_SDF_EXACT,
    HV_SDF_HEAT,
    HV_SDF_REPAIR_ALL,
    HV_SDF_REPAIR_DOMED_CAPS,
    backend_code,
    backend_name,
    fn,
    fspath,
    hv_grid,
    hv_sdf_opts,
    hv_tiles_sink,
    hv_sdf_stats,
    progress_scope,
    struct_dict,
)
from ._mesh import c_mesh, read_mesh
from ._points import is_points_file, read_points, surface_of_points


def _shape(path, o):
    """(vertices, faces) of a mesh file, or of the surface through a point
    cloud's file (placed with o; its normals recovered as o.orient says)."""
    if is_points_file(path):
        v, f, _ = surface_of_points(*read_points(path), o)
        return v, f
    return read_mesh(path)

def _opts(res, pad, voxel_size, bbox, band, unsigned, backend, heat, t_scale, heat_coarsen, sign,
          repair, domed_caps, threads, more):
    """hv_sdf_opts from sdf()'s arguments, and the band (default 3)."""
    o = hv_sdf_opts()
    fn.hv_sdf_opts_default(ctypes.byref(o))
    if voxel_size is not None:
        o.voxel_size = _arrays.positive(voxel_size, "voxel_size")
    else:
        o.res = _arrays.integer(res, "res", 1)
        o.voxel_size = 0
    o.pad = _arrays.integer(pad, "pad", 0)
    if bbox is not None:
        b = np.asarray(bbox, dtype=np.float64).ravel()
        if b.size != 6 or not np.all(np.isfinite(b)):
            raise ValueError("bbox must be 6 finite numbers (x0, y0, z0, x1, y1, z1), got %r" % (bbox,))
        for a in range(3):
            if not b[3 + a] > b[a]:
                raise ValueError("bbox: %s1 (%g) must exceed %s0 (%g)" % ("xyz"[a], b[3 + a], "xyz"[a], b[a]))
        o.use_bbox = 1
        o.bbox[:] = list(b)
    band = 3.0 if band is None else _arrays.positive(band, "band")
    o.unsigned_distance = 1 if unsigned else 0
    o.backend = backend_code(backend)
    o.magnitude = HV_SDF_HEAT if heat else HV_SDF_EXACT
    o.t_scale = _arrays.positive(t_scale, "t_scale")
    o.heat_coarsen = _arrays.integer(heat_coarsen, "heat_coarsen", 0, 4)
    signs = {"auto": 0, "heat": 1, "winding": 2}
    if sign not in signs:
        raise ValueError("sign must be one of 'auto', 'heat', 'winding', got %r" % (sign,))
    o.sign = signs[sign]
    if repair is True:
        flags = HV_SDF_REPAIR_ALL
    elif repair is False:
        flags = 0
    else:
        flags = _arrays.integer(repair, "repair", 0, 0x7F)
    o.repair = flags | (HV_SDF_REPAIR_DOMED_CAPS if domed_caps else 0)
    o.threads = _arrays.integer(threads, "threads", 0, HV_MAX_THREADS)
    for key, value in more.items():
        check = _MORE.get(key)
        if check is None:
            raise TypeError("sdf() got an unexpected keyword argument %r (hv_sdf_opts fields: %s)" % (key, ", ".join(sorted(_MORE))))
        setattr(o, key, check(value))

    return o, band


_ORIENTS = {"auto": 0, "given": 1, "recover": 2}


def _orient_code(x):
    if x not in _ORIENTS:
        raise ValueError("orient must be one of 'auto', 'given', 'recover', got %r" % (x,))
    return _ORIENTS[x]


# hv_sdf_opts fields that sdf() takes through **more, with their checks.
_MORE = {
    "round_to": lambda x: _arrays.integer(x, "round_to", 1),
    "far_levels": lambda x: _arrays.integer(x, "far_levels", -1),
    "max_hole": lambda x: _arrays.real(x, "max_hole", 0.0),
    "near_sign": lambda x: _arrays.real(x, "near_sign", 0.0),
    "local_shift": lambda x: 1 if x else 0,
    "band_only": lambda x: _arrays.real(x, "band_only", 0.0),
    "diffuse_tol": lambda x: _arrays.real(x, "diffuse_tol", 0.0),
    "poisson_tol": lambda x: _arrays.real(x, "poisson_tol", 0.0),
    # a point cloud's normals: "auto" (recovered when it has none), "given", "recover"
    "orient": lambda x: _orient_code(x),
    # morphology in world units (sdf.h): close and open run on the dense grid
    "close": lambda x: _arrays.real(x, "close", 0.0),
    "open": lambda x: _arrays.real(x, "open", 0.0),
    "offset": lambda x: _arrays.real(x, "offset"),
    "shell": lambda x: _arrays.real(x, "shell", 0.0),
}


def sdf(
    vertices,
    faces=None,
    res=128,
    pad=4,
    voxel_size=None,
    bbox=None,
    band=None,
    unsigned=False,
    backend="auto",
    *,
    heat=False,
    t_scale=1.0,
    heat_coarsen=0,
    sign="auto",
    repair=True,
    domed_caps=False,
    threads=0,
    progress=None,
    **more,
):
    """Signed (or unsigned) distance volume of a triangle mesh by the signed
    heat method, robust to holes, flipped faces, duplicated sheets, soups
    and self-intersections: what ``heatvox sdf`` computes.

    ``sdf(vertices, faces, ...)`` with a float (n, 3) array and an integer
    (m, 3) array (``read_mesh`` gives both), or ``sdf(path, ...)`` to read
    the mesh file; a path to an oriented point cloud (see
    ``read_points``) gets the distance to its surface (``points_surface``),
    as the command does. The options and defaults are the command's, and the
    result's ``values`` are bit for bit the command's ``--npy`` output for
    the same options:

    Grid placement (cell-centred):
      res          cells along the longest side of the mesh bounds plus 2*pad
                   (default 128); cell counts are rounded up to a multiple of
                   8, the extra padding centred (``--res``)
      pad          cells between the mesh bounds and the block (default 4)
      voxel_size   the voxel size instead of ``res`` (``--voxel-size``)
      bbox         (x0, y0, z0, x1, y1, z1): the outer boundary of the voxel
                   block instead (with ``res``: h = longest side / res; pad
                   is ignored) (``--bbox``)
    Output:
      band         half width in voxels of the narrow band that
                   ``Grid.write_vdb`` writes (default 3, ``--band``); the
                   values themselves are exact over the whole grid, as the
                   command's ``--npy``
      unsigned     the unsigned distance (``--unsigned``); the grid is then
                   no level set
    Method:
      backend      linear solver: "auto", "mg", "fftw", "opencl"
      heat         keep the heat method's own magnitude instead of the exact
                   distance to the triangles (``--heat``)
      t_scale      diffusion time t = (t_scale h)^2 (default 1)
      heat_coarsen run the heat method (which then only decides the sign) on
                   a grid 1..4 times coarser; 0: 2 above 2^22 cells, else 1
      sign         where the sign comes from: "auto" (the winding number of
                   the repaired mesh when it stays open or the block cuts it,
                   so that the answer does not depend on the block; the heat
                   method otherwise), "heat" or "winding" (``--sign``)
      repair       True (default): weld, drop degenerate and duplicate faces,
                   orient, fill holes, turn outward; False: none
                   (``--no-repair``); or an int of HV_SDF_REPAIR_* flags
      domed_caps   close holes with caps that bulge like the wall around
                   them (``--domed-caps``)
      threads      worker threads (process-wide); 0 leaves the setting
      progress     callable(fraction, stage) -> bool or None, called between
                   stages; a true return value cancels (heatvox.Error with
                   status CANCELLED)
    ``**more`` sets further fields of hv_sdf_opts (sdf.h): ``band_only`` (> 0:
    exact distances only within that many voxels of the mesh, farther cells
    get (band_only + 1) h with the right sign: much faster when only a narrow
    band is needed, which is what the command does when it writes only a
    .vdb), ``round_to``, ``far_levels``, ``max_hole``, ``near_sign``,
    ``local_shift``, ``diffuse_tol``, ``poisson_tol``.

    Returns a :class:`Grid` (negative inside) with ``stats``: a dict of
    hv_sdf_stats (grid, seconds per stage, solver iterations and residuals,
    and the repair report under "repair"). Raises heatvox.Error (mesh
    file errors name the file), TypeError or ValueError for bad arguments.
    """
    if faces is None and not is_path(vertices):
        raise TypeError("sdf needs (vertices, faces) arrays or a mesh path")
    o, band = _opts(res, pad, voxel_size, bbox, band, unsigned, backend, heat, t_scale,
                    heat_coarsen, sign, repair, domed_caps, threads, more)
    if faces is None:
        vertices, faces = _shape(vertices, o)
    out = ctypes.POINTER(hv_grid)()
    st = hv_sdf_stats()
    with c_mesh(vertices, faces) as mesh, progress_scope(progress):
        fn.hv_sdf_compute(mesh, ctypes.byref(o), ctypes.byref(out), ctypes.byref(st))
    stats = struct_dict(st)
    stats["backend"] = backend_name(st.backend)
    stats["sign"] = {0: None, 1: "heat", 2: "winding"}.get(st.sign)
    return Grid._adopt(out, levelset=not unsigned, band=band, name="sdf", stats=stats)


def sdf_vdb(
    vertices,
    faces=None,
    path=None,
    res=128,
    pad=4,
    voxel_size=None,
    bbox=None,
    band=None,
    *,
    sign="auto",
    repair=True,
    domed_caps=False,
    threads=0,
    name="sdf",
    metadata=None,
    progress=None,
    **more,
):
    """Writes the narrow-band level set of a triangle mesh to an OpenVDB file
    without the dense block, as ``heatvox sdf MESH -o PATH`` does: the band
    is computed in 8^3 tiles near the surface (memory and time follow the
    surface: a 1024^3 or 2048^3 band fits where the dense grid would not)
    and written from them.

    ``sdf_vdb(vertices, faces, path, ...)`` or ``sdf_vdb(mesh_path,
    path=path, ...)``. Placement (``res``, ``pad``, ``voxel_size``,
    ``bbox``), ``band`` (half width in voxels, default 3), ``repair``,
    ``domed_caps``, ``threads``, ``progress`` and ``**more`` (``near_sign``,
    ``max_hole``, ``round_to``) are sdf()'s; the values on the band equal
    ``sdf(..., band_only=band, sign="winding")``'s. ``sign``: "auto" or
    "winding" (the tiles' sign is the winding number's; "heat" needs the
    dense block: use sdf()). ``name``: the grid's name; ``metadata``: a dict
    of file metadata strings. The file lands through a temporary name, or
    not at all.

    Returns the stats dict (as sdf()'s, with "tiles" and "active_voxels").
    Raises heatvox.Error naming the mesh or the file.
    """
    if faces is not None and path is None and is_path(faces):
        faces, path = None, faces
    if path is None:
        raise TypeError("sdf_vdb needs the output path")
    if faces is None and not is_path(vertices):
        raise TypeError("sdf_vdb needs (vertices, faces) arrays or a mesh path")
    if sign == "heat":
        raise ValueError("sdf_vdb's tiles take the winding number's sign; use sdf(sign='heat')")
    o, band = _opts(res, pad, voxel_size, bbox, band, False, "auto", False, 1.0, 0, sign,
                    repair, domed_caps, threads, more)
    if faces is None:
        vertices, faces = _shape(vertices, o)
    if not str(name):
        raise ValueError("name must not be empty")
    st = hv_sdf_stats()
    w = ctypes.c_void_p()
    sink = hv_tiles_sink()
    # The tiles go into the writer's tree as they are computed: the band is
    # never held twice.
    try:
        fn.hv_vdb_writer_create(ctypes.byref(w))
        fn.hv_vdb_writer_levelset_sink(w, str(name).encode(), band, None, ctypes.byref(sink))
        with c_mesh(vertices, faces) as mesh, progress_scope(progress):
            fn.hv_sdf_stream_tiles(mesh, ctypes.byref(o), band, ctypes.byref(sink), ctypes.byref(st))
        fn.hv_vdb_writer_set_meta(w, b"heatvox_version", fn.hv_version())
        for k, v in (metadata or {}).items():
            fn.hv_vdb_writer_set_meta(w, str(k).encode(), str(v).encode())
        fn.hv_vdb_writer_write(w, fspath(path))
    finally:
        fn.hv_vdb_writer_destroy(ctypes.byref(w))
    stats = struct_dict(st)
    stats["backend"] = None
    stats["sign"] = {0: None, 1: "heat", 2: "winding"}.get(st.sign)
    return stats
