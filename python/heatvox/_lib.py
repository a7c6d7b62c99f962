"""ctypes declarations of libheatvox: the library, its structs and its functions.

Every struct mirrors its C declaration field by field and in order (the headers
under include/heatvox/ are the reference; tests/python/test_structs.py compares
sizes and offsets with a C compiler). Every function used here gets argtypes and
restype; functions returning hv_status raise heatvox.Error through errcheck.
"""

import ctypes
import enum
import os
import threading
from ctypes import (
    CFUNCTYPE,
    POINTER,
    Structure,
    c_char_p,
    c_double,
    c_float,
    c_int,
    c_int32,
    c_size_t,
    c_uint,
    c_uint8,
    c_uint32,
    c_uint64,
    c_void_p,
)

# The ABI these declarations describe: libheatvox.so.0 (the soname carries the
# major version and changes when the interface breaks).
SONAME = "libheatvox.so.0"

# ---- loading ---------------------------------------------------------------


def _candidates():
    """Where to look for the library, in order (see load())."""
    env = os.environ.get("HEATVOX_LIBRARY")
    if env:
        return [env]
    here = os.path.dirname(os.path.abspath(__file__))
    found = [os.path.join(here, SONAME)]  # bundled by the wheel (setup.py)
    try:
        from . import _install  # written by `make install`

        found.append(os.path.join(_install.LIBDIR, _install.SONAME))
    except ImportError:
        pass
    found.append(os.path.normpath(os.path.join(here, "..", "..", "build", "libheatvox.so")))
    found.append(SONAME)  # the dynamic loader's search (ldconfig, LD_LIBRARY_PATH)
    return found


def _loaded_path(name):
    """The file the loader mapped for `name` (Linux: /proc/self/maps)."""
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                p = line.split(None, 5)
                if len(p) == 6 and "/libheatvox.so" in p[5]:
                    return p[5].strip()
    except OSError:
        pass
    return name


def load():
    """Loads libheatvox: $HEATVOX_LIBRARY alone when set, else the copy a
    wheel bundles beside this file (heatvox/libheatvox.so.0, from pip
    install), else the library `make install` recorded, else the in-tree build
    (../../build/libheatvox.so from this package), else libheatvox.so.0
    through the dynamic loader. Returns (CDLL, path)."""
    # libgomp's threads spin at every barrier; on a busy machine that makes
    # solves many times slower (README, "Backends and environment"). The
    # command lowers the spin count for itself; do the same before libgomp is
    # loaded, unless the user chose a policy.
    if "GOMP_SPINCOUNT" not in os.environ and "OMP_WAIT_POLICY" not in os.environ:
        os.environ["GOMP_SPINCOUNT"] = "1000"
    tried = []
    for cand in _candidates():
        if os.path.sep in cand and not os.path.exists(cand) and not os.environ.get("HEATVOX_LIBRARY"):
            tried.append("%s (not there)" % cand)
            continue
        try:
            lib = ctypes.CDLL(cand)
        except OSError as e:
            tried.append("%s (%s)" % (cand, e))
            continue
        return lib, _loaded_path(cand)
    raise ImportError("heatvox: cannot load libheatvox; tried: " + "; ".join(tried))


dll, path = load()

# ---- status codes and errors ------------------------------------------------


class Status(enum.IntEnum):
    """hv_status codes (core.h)."""

    OK = 0
    INVALID_ARG = 1
    NOMEM = 2
    IO = 3
    PARSE = 4
    NUMERIC = 5
    UNSUPPORTED = 6
    BACKEND = 7
    CANCELLED = 8
    INTERNAL = 9


class Error(Exception):
    """A libheatvox call failed.

    Attributes: ``status`` (a :class:`Status`), ``name`` (hv_status_str, e.g.
    "i/o error") and ``message`` (hv_last_error(): the detail, naming the file,
    line or argument where it applies). ``str(err)`` is "name: message".
    """

    def __init__(self, status, message):
        try:
            self.status = Status(status)
        except ValueError:
            self.status = status
        self.name = fn.hv_status_str(int(status)).decode()
        self.message = message
        super().__init__("%s: %s" % (self.name, message) if message else self.name)


def _errcheck(result, func, args):
    if result != 0:
        raise Error(result, fn.hv_last_error().decode(errors="replace"))
    return result


# ---- structs (field order as in the headers) --------------------------------


class hv_grid(Structure):
    _fields_ = [
        ("dim", c_int),
        ("n", c_int * 3),
        ("h", c_double),
        ("origin", c_double * 3),
        ("v", POINTER(c_float)),
        ("solid", POINTER(c_uint8)),
    ]


class hv_tiles(Structure):
    _fields_ = [
        ("n", c_int * 3),
        ("h", c_double),
        ("origin", c_double * 3),
        ("count", c_size_t),
        ("ijk", POINTER(c_int32)),
        ("v", POINTER(c_float)),
        ("on", POINTER(c_uint64)),
        ("active", c_size_t),
    ]


class hv_tiles_sink(Structure):
    # The library's own sinks only (hv_vdb_writer_levelset_sink): their
    # function pointers go back to C as they came.
    _fields_ = [
        ("user", c_void_p),
        ("begin", c_void_p),
        ("put", c_void_p),
        ("end", c_void_p),
    ]


class hv_vdb_sink_stats(Structure):
    _fields_ = [
        ("batches", c_size_t),
        ("tiles", c_size_t),
        ("leaves", c_size_t),
        ("tree_bytes", c_double),
        ("packed_leaves", c_size_t),
        ("packed_bytes", c_double),
        ("tree_bytes_bound", c_double),
        ("t_leaves", c_double),
        ("t_fill", c_double),
    ]


class hv_mesh(Structure):
    _fields_ = [
        ("nverts", c_size_t),
        ("ntris", c_size_t),
        ("verts", POINTER(c_double)),
        ("tris", POINTER(c_uint32)),
        ("format", c_char_p),
        ("input_vertices", c_size_t),
        ("unreferenced_vertices", c_size_t),
        ("polygons_fanned", c_size_t),
        ("nonfinite_vertex", c_size_t),
        ("nonfinite_line", c_size_t),
        ("unit_meters", c_double),
        ("skipped_primitives", c_size_t),
    ]


class hv_mesh_report(Structure):
    _fields_ = [
        ("vertices", c_size_t),
        ("triangles", c_size_t),
        ("polygons_fanned", c_size_t),
        ("boundary_edges", c_size_t),
        ("nonmanifold_edges", c_size_t),
        ("inconsistent_edges", c_size_t),
        ("duplicate_faces", c_size_t),
        ("degenerate_faces", c_size_t),
        ("nonfinite_vertices", c_size_t),
        ("components", c_size_t),
        ("edges", c_size_t),
        ("vertex_components", c_size_t),
        ("input_vertices", c_size_t),
        ("unreferenced_vertices", c_size_t),
        ("signed_volume", c_double),
    ]


class hv_problem(Structure):
    _fields_ = [
        ("dim", c_int),
        ("n", c_int * 3),
        ("h", c_double),
        ("solid", POINTER(c_uint8)),
        ("alpha", c_double),
        ("beta", c_double),
    ]


class hv_solver_opts(Structure):
    _fields_ = [
        ("backend", c_int),
        ("smoother", c_int),
        ("tol", c_double),
        ("max_iter", c_int),
        ("pre_smooth", c_int),
        ("post_smooth", c_int),
        ("nonzero_guess", c_int),
        ("fftw_double", c_int),
        ("wisdom_file", c_char_p),
        ("fftw_measure", c_int),
        ("cycles_per_iteration", c_int),
        ("coarse", c_int),
    ]


HV_MAX_HISTORY = 64


class hv_solve_info(Structure):
    _fields_ = [
        ("backend", c_int),
        ("reason", c_int),
        ("iterations", c_int),
        ("cycles", c_int),
        ("relres", c_double),
        ("nhistory", c_int),
        ("history", c_double * HV_MAX_HISTORY),
        ("seconds", c_double),
        ("cycles_timed", c_int),
        ("cycle_seconds", c_double),
        ("cycle_bytes", c_double),
    ]


class hv_sdf_opts(Structure):
    _fields_ = [
        ("res", c_int),
        ("voxel_size", c_double),
        ("pad", c_int),
        ("use_bbox", c_int),
        ("bbox", c_double * 6),
        ("round_to", c_int),
        ("unsigned_distance", c_int),
        ("magnitude", c_int),
        ("t_scale", c_double),
        ("far_levels", c_int),
        ("repair", c_uint),
        ("max_hole", c_double),
        ("near_sign", c_double),
        ("local_shift", c_int),
        ("band_only", c_double),
        ("backend", c_int),
        ("diffuse_tol", c_double),
        ("poisson_tol", c_double),
        ("heat_coarsen", c_int),
        ("threads", c_int),
        ("sign", c_int),
        ("close", c_double),
        ("open", c_double),
        ("offset", c_double),
        ("shell", c_double),
        ("orient", c_int),
    ]


class hv_sdf_repair_report(Structure):
    _fields_ = [
        (name, c_size_t)
        for name in (
            "vertices_in",
            "triangles_in",
            "vertices_welded",
            "degenerate_removed",
            "duplicates_removed",
            "holes_filled",
            "holes_left_open",
            "cap_triangles",
            "boundary_edges_closed",
            "boundary_edges",
            "nonmanifold_edges",
            "inconsistent_before",
            "inconsistent_after",
            "components",
            "faces_flipped",
            "components_flipped",
            "vertices_out",
            "triangles_out",
        )
    ]


class hv_sdf_stats(Structure):
    _fields_ = [
        ("n", c_int * 3),
        ("h", c_double),
        ("origin", c_double * 3),
        ("t", c_double),
        ("levels", c_int),
        ("heat_coarsen", c_int),
        ("backend", c_int),
        ("surface_samples", c_size_t),
        ("t_repair", c_double),
        ("t_splat", c_double),
        ("t_diffuse", c_double),
        ("t_normalize", c_double),
        ("t_poisson", c_double),
        ("t_shift", c_double),
        ("t_redistance", c_double),
        ("t_total", c_double),
        ("diffuse_iterations", c_int),
        ("diffuse_relres", c_double),
        ("poisson_iterations", c_int),
        ("poisson_relres", c_double),
        ("shift", c_double),
        ("surface_rms_before", c_double),
        ("surface_rms_after", c_double),
        ("dead_faces", c_size_t),
        ("band_cells", c_size_t),
        ("near_sign_cells", c_size_t),
        ("near_sign_changed", c_size_t),
        ("repair", hv_sdf_repair_report),
        ("sign", c_int),
        ("winding_evals", c_size_t),
        ("t_sign", c_double),
        ("tiles", c_size_t),
        ("active_voxels", c_size_t),
        ("tiles_in_flight", c_size_t),
        ("tiles_bound", c_size_t),
    ]


class hv_points(Structure):
    _fields_ = [
        ("count", c_size_t),
        ("xyz", POINTER(c_double)),
        ("normals", POINTER(c_double)),
        ("format", c_char_p),
    ]


class hv_points_report(Structure):
    _fields_ = [
        ("points", c_size_t),
        ("spacing_median", c_double),
        ("spacing_min", c_double),
        ("spacing_max", c_double),
        ("normals_against", c_size_t),
        ("normal_agreement", c_double),
        ("vertices", c_size_t),
        ("vertices_unsupported", c_size_t),
        ("move_mean", c_double),
        ("move_max", c_double),
        ("noise", c_double),
        ("sigma", c_double),
        ("n", c_int * 3),
        ("h", c_double),
        ("coarsen", c_int),
        ("heat", hv_sdf_stats),
        ("t_spacing", c_double),
        ("t_heat", c_double),
        ("t_mesh", c_double),
        ("t_project", c_double),
        ("t_total", c_double),
        ("recovered", c_int),
        ("orient_components", c_size_t),
        ("orient_components_flipped", c_size_t),
        ("orient_rounds", c_int),
        ("orient_turned", c_size_t),
        ("orient_disagree", c_size_t),
        ("t_orient", c_double),
        ("orient_spread", c_double),
        ("orient_lines", c_int),
        ("orient_line_iterations", c_int),
        ("orient_thin_votes", c_size_t),
        ("orient_thin_turned", c_size_t),
    ]


class hv_distance_sources(Structure):
    _fields_ = [
        ("voxels", POINTER(c_int)),
        ("nvoxels", c_size_t),
        ("points", POINTER(c_double)),
        ("npoints", c_size_t),
        ("mesh", POINTER(hv_mesh)),
    ]


class hv_distance_opts(Structure):
    _fields_ = [
        ("t_scale", c_double),
        ("max_stages", c_int),
        ("diffuse_tol", c_double),
        ("poisson_tol", c_double),
        ("backend", c_int),
        ("unreachable", c_float),
        ("solid_value", c_float),
        ("coarse", c_int),
        ("whole_stages", c_int),
    ]


class hv_distance_stats(Structure):
    _fields_ = [
        ("t", c_double),
        ("stages", c_int),
        ("faces_per_stage", c_size_t * 8),
        ("dead_faces", c_size_t),
        ("source_cells", c_size_t),
        ("sources_in_solid", c_size_t),
        ("regions", c_size_t),
        ("unreachable_cells", c_size_t),
        ("diffuse_iterations", c_int),
        ("diffuse_relres", c_double),
        ("poisson_iterations", c_int),
        ("poisson_restarts", c_int),
        ("poisson_relres", c_double),
        ("backend", c_int),
        ("t_splat", c_double),
        ("t_diffuse", c_double),
        ("t_normalize", c_double),
        ("t_poisson", c_double),
        ("t_total", c_double),
        ("cells_solved", c_size_t),
        ("stage_cells", c_size_t * 8),
        ("t_setup", c_double),
        ("host_bytes", c_double),
    ]


class hv_extend_opts(Structure):
    _fields_ = [
        ("band", c_double),
        ("t_scale", c_double),
        ("closest_point", c_int),
        ("out_band", c_double),
        ("background", c_float),
        ("max_levels", c_int),
        ("backend", c_int),
        ("tol", c_double),
        ("box_only", c_int),
    ]


class hv_extend_stats(Structure):
    _fields_ = [
        ("source_cells", c_size_t),
        ("cp_cells", c_size_t),
        ("ratio_cells", c_size_t),
        ("weak_cells", c_size_t),
        ("levels", c_int),
        ("solve_cells", c_size_t),
        ("solves", c_int),
        ("relres", c_double),
        ("t_weights", c_double),
        ("t_solve", c_double),
        ("t_eval", c_double),
        ("t_total", c_double),
        ("tiles", c_size_t),
        ("work_bytes", c_size_t),
        ("remote_cells", c_size_t),
        ("on_device", c_int),
    ]


class hv_extend_field(Structure):
    _fields_ = [
        ("ncomp", c_int),
        ("in_", POINTER(c_float) * 3),  # `in` in C (a Python keyword)
        ("out", POINTER(c_float) * 3),
    ]


# Every struct above, by its C name (for tests/python/test_structs.py).
STRUCTS = [
    hv_grid,
    hv_tiles,
    hv_tiles_sink,
    hv_vdb_sink_stats,
    hv_mesh,
    hv_mesh_report,
    hv_problem,
    hv_solver_opts,
    hv_solve_info,
    hv_sdf_opts,
    hv_sdf_repair_report,
    hv_sdf_stats,
    hv_points,
    hv_points_report,
    hv_distance_sources,
    hv_distance_opts,
    hv_distance_stats,
    hv_extend_opts,
    hv_extend_stats,
    hv_extend_field,
]

# Constants of the headers.
HV_SDF_REPAIR_ALL = 0x3F
HV_SDF_REPAIR_DOMED_CAPS = 1 << 6
HV_SDF_EXACT = 0
HV_SDF_HEAT = 1
HV_MAX_THREADS = 1024
HV_VDB_LEVEL_SET = 1

PROGRESS_FN = CFUNCTYPE(c_int, c_double, c_char_p, c_void_p)

# ---- functions ----------------------------------------------------------------

_P = POINTER
_grid_p = _P(hv_grid)
_mesh_p = _P(hv_mesh)
_writer_p = c_void_p  # hv_vdb_writer *
_status = object()  # marks functions that return hv_status

_PROTOTYPES = {
    # core.h
    "hv_status_str": (c_char_p, [c_int]),
    "hv_last_error": (c_char_p, []),
    "hv_clear_error": (None, []),
    "hv_set_progress": (None, [PROGRESS_FN, c_void_p]),
    "hv_version": (c_char_p, []),
    "hv_set_threads": (None, [c_int]),
    "hv_get_threads": (c_int, []),
    "hv_peak_rss": (c_size_t, []),
    "hv_peak_rss_reset": (_status, []),
    # grid.h
    "hv_grid_create": (_status, [_P(_grid_p), c_int, _P(c_int), c_double, _P(c_double)]),
    "hv_grid_destroy": (None, [_P(_grid_p)]),
    # mesh.h
    "hv_mesh_read": (_status, [c_char_p, _P(_mesh_p)]),
    "hv_mesh_from_arrays": (_status, [_P(_mesh_p), c_void_p, c_size_t, c_void_p, c_size_t]),
    "hv_mesh_destroy": (None, [_P(_mesh_p)]),
    "hv_points_file": (c_int, [c_char_p]),
    "hv_points_read": (_status, [c_char_p, _P(_P(hv_points))]),
    "hv_points_from_arrays": (_status, [_P(_P(hv_points)), c_void_p, c_void_p, c_size_t]),
    "hv_points_destroy": (None, [_P(_P(hv_points))]),
    "hv_mesh_report_compute": (_status, [_mesh_p, _P(hv_mesh_report)]),
    # io.h
    "hv_write_npy": (_status, [c_char_p, _grid_p]),
    # solve.h
    "hv_backend_name": (c_char_p, [c_int]),
    "hv_backend_parse": (c_int, [c_char_p, _P(c_int)]),  # status checked by the caller
    "hv_stop_reason_str": (c_char_p, [c_int]),
    "hv_solver_opts_default": (None, [_P(hv_solver_opts)]),
    "hv_solver_create": (_status, [_P(c_void_p), _P(hv_problem), _P(hv_solver_opts)]),
    "hv_solver_solve": (_status, [c_void_p, c_void_p, c_void_p, _P(hv_solve_info)]),
    "hv_solver_solve_d": (_status, [c_void_p, c_void_p, c_void_p, _P(hv_solve_info)]),
    "hv_solver_backend": (c_int, [c_void_p]),
    "hv_solver_destroy": (None, [_P(c_void_p)]),
    # sdf.h
    "hv_sdf_opts_default": (None, [_P(hv_sdf_opts)]),
    "hv_points_surface": (_status, [_P(hv_points), _P(hv_sdf_opts), _P(_mesh_p), _P(hv_points_report)]),
    "hv_sdf_compute": (_status, [_mesh_p, _P(hv_sdf_opts), _P(_grid_p), _P(hv_sdf_stats)]),
    "hv_sdf_compute_tiles": (
        _status,
        [_mesh_p, _P(hv_sdf_opts), c_double, _P(_P(hv_tiles)), _P(hv_sdf_stats)],
    ),
    "hv_sdf_stream_tiles": (
        _status,
        [_mesh_p, _P(hv_sdf_opts), c_double, _P(hv_tiles_sink), _P(hv_sdf_stats)],
    ),
    "hv_tiles_destroy": (None, [_P(_P(hv_tiles))]),
    # heat.h
    "hv_distance_opts_default": (None, [_P(hv_distance_opts)]),
    "hv_distance_compute": (
        _status,
        [_grid_p, _P(hv_distance_sources), _P(hv_distance_opts), _P(hv_distance_stats)],
    ),
    "hv_distance_create": (_status, [_P(c_void_p), _grid_p, _P(hv_distance_opts)]),
    "hv_distance_query": (
        _status,
        [c_void_p, _P(hv_distance_sources), _grid_p, _P(hv_distance_stats)],
    ),
    "hv_distance_destroy": (None, [_P(c_void_p)]),
    "hv_mask_from_mesh": (_status, [_grid_p, _mesh_p, _P(c_size_t)]),
    "hv_extend_opts_default": (None, [_P(hv_extend_opts)]),
    "hv_extender_create": (
        _status,
        [_P(c_void_p), c_int, _P(c_int), c_double, c_void_p, _P(hv_extend_opts)],
    ),
    "hv_extender_destroy": (None, [_P(c_void_p)]),
    "hv_extend_many": (
        _status,
        [c_void_p, c_void_p, c_int, _P(hv_extend_field), _P(hv_extend_stats)],
    ),
    # vdb.h
    "hv_vdb_writer_create": (_status, [_P(_writer_p)]),
    "hv_vdb_writer_destroy": (None, [_P(_writer_p)]),
    "hv_vdb_writer_add_levelset": (_status, [_writer_p, _grid_p, c_char_p, c_double, c_int]),
    "hv_vdb_writer_add_float": (_status, [_writer_p, _grid_p, c_char_p]),
    "hv_vdb_writer_add_fog": (_status, [_writer_p, _grid_p, c_char_p]),
    "hv_vdb_writer_add_levelset_tiles": (_status, [_writer_p, _P(hv_tiles), c_char_p, c_double]),
    "hv_vdb_writer_levelset_sink": (
        _status,
        [_writer_p, c_char_p, c_double, _P(hv_vdb_sink_stats), _P(hv_tiles_sink)],
    ),
    "hv_vdb_writer_add_mask": (_status, [_writer_p, _grid_p, c_char_p]),
    "hv_vdb_writer_set_meta": (_status, [_writer_p, c_char_p, c_char_p]),
    "hv_vdb_writer_write": (_status, [_writer_p, c_char_p]),
    "hv_grid_to_mesh": (_status, [_grid_p, c_double, c_double, _P(_mesh_p)]),
}


class _Functions:
    """The prototyped functions, bound on first use: a library built without
    one of them (an older copy) still loads, and the call that needs the
    missing function raises Error(UNSUPPORTED) naming it."""

    def __init__(self, dll):
        self._dll = dll
        self._lock = threading.Lock()

    def __getattr__(self, name):
        proto = _PROTOTYPES.get(name)
        if proto is None:
            raise AttributeError(name)
        with self._lock:
            try:
                fn = getattr(self._dll, name)
            except AttributeError:
                raise Error(
                    Status.UNSUPPORTED, "%s is not in the loaded library %s" % (name, path)
                ) from None
            restype, argtypes = proto
            fn.argtypes = argtypes
            if restype is _status:
                fn.restype = c_int
                fn.errcheck = _errcheck
            else:
                fn.restype = restype
            setattr(self, name, fn)
        return fn


fn = _Functions(dll)

# ---- progress -----------------------------------------------------------------

# hv_set_progress is process-wide: calls given a progress callback take this
# lock, so that two threads never swap each other's callbacks.
_progress_lock = threading.RLock()
_progress_current = [None]  # the CFUNCTYPE object installed now (None: none)


class progress_scope:
    """Installs `callback(fraction, stage)` with hv_set_progress for the body of
    a with block and restores the previous one afterwards. A true return value
    cancels the running call (HV_ERR_CANCELLED); an exception raised by the
    callback cancels it too and is re-raised in place of the Error."""

    def __init__(self, callback):
        if callback is not None and not callable(callback):
            raise TypeError("progress must be callable(fraction, stage) or None, got %r" % (callback,))
        self.callback = callback
        self.exc = None

    def _call(self, fraction, stage, user):
        if self.exc is not None:
            return 1
        try:
            return 1 if self.callback(fraction, stage.decode(errors="replace") if stage else "") else 0
        except BaseException as e:  # noqa: B902 (KeyboardInterrupt cancels too)
            self.exc = e
            return 1

    def __enter__(self):
        if self.callback is None:
            return self
        _progress_lock.acquire()
        self._prev = _progress_current[0]
        self._cfn = PROGRESS_FN(self._call)  # kept alive for the call
        fn.hv_set_progress(self._cfn, None)
        _progress_current[0] = self._cfn
        return self

    def __exit__(self, etype, evalue, tb):
        if self.callback is None:
            return False
        fn.hv_set_progress(self._prev if self._prev is not None else PROGRESS_FN(), None)
        _progress_current[0] = self._prev
        _progress_lock.release()
        if self.exc is not None and isinstance(evalue, Error) and evalue.status == Status.CANCELLED:
            raise self.exc from evalue
        return False


# ---- small helpers ----------------------------------------------------------------


_COARSE = {"auto": 0, "geometric": 1, "aggregation": 2}


def coarse_code(coarse):
    """hv_coarse of "auto", "geometric" or "aggregation" (ValueError otherwise)."""
    if coarse not in _COARSE:
        raise ValueError("coarse must be one of %s, got %r" % (", ".join(_COARSE), coarse))
    return _COARSE[coarse]


def backend_code(name):
    """hv_backend for "auto", "mg", "fftw" or "opencl" (ValueError otherwise)."""
    if not isinstance(name, str):
        raise TypeError("backend must be a string (auto, mg, fftw, opencl), got %r" % (name,))
    out = c_int(0)
    if fn.hv_backend_parse(name.encode(), ctypes.byref(out)) != 0:
        fn.hv_clear_error()
        raise ValueError("backend must be auto, mg, fftw or opencl, got %r" % (name,))
    return out.value


def backend_name(code):
    return fn.hv_backend_name(code).decode()


def struct_dict(s):
    """A ctypes struct as a dict (arrays as lists, nested structs as dicts)."""
    out = {}
    for name, ctype in s._fields_:
        v = getattr(s, name)
        if isinstance(v, Structure):
            v = struct_dict(v)
        elif isinstance(v, ctypes.Array):
            v = list(v)
        elif isinstance(v, bytes):
            v = v.decode(errors="replace")
        out[name] = v
    return out


def fspath(p):
    """A path argument as bytes for C (str, bytes or os.PathLike)."""
    try:
        return os.fsencode(p)
    except TypeError:
        raise TypeError("expected a path (str, bytes or os.PathLike), got %r" % (p,)) from None
