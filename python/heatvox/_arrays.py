"""NumPy arrays over library memory, and NumPy arrays handed to C."""

import ctypes
import numbers

import numpy as np


class _View:
    """Exposes library memory to NumPy: np.asarray(view) has this object as its
    base, and this object keeps `owner` (the object that frees the memory)
    alive, so the array can outlive every other reference to its owner."""

    def __init__(self, owner, address, shape, dtype):
        self._owner = owner
        self.__array_interface__ = {
            "version": 3,
            "shape": tuple(shape),
            "typestr": np.dtype(dtype).str,
            "data": (address, False),
        }


def view(owner, address, shape, dtype):
    """A writable NumPy array of `shape` and `dtype` at `address`, keeping `owner` alive."""
    return np.asarray(_View(owner, address, shape, dtype))


def address(a):
    """The data address of a NumPy array, as a ctypes void pointer."""
    return ctypes.c_void_p(a.ctypes.data)


def c_array(a, dtype, name, writable=False):
    """`a` as a C-contiguous NumPy array of `dtype`: the array itself when it
    already is one (no copy), else a converted copy. TypeError when it cannot
    be read as numbers."""
    try:
        arr = np.asarray(a)
    except Exception as e:  # pragma: no cover - odd objects
        raise TypeError("%s: cannot be read as an array (%s)" % (name, e)) from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_):
        raise TypeError("%s: expected a numeric array, got dtype %s" % (name, arr.dtype))
    if arr.dtype != dtype or not arr.flags.c_contiguous:
        arr = np.ascontiguousarray(arr, dtype=dtype)
    if writable and not arr.flags.writeable:
        raise ValueError("%s: the array is read-only" % name)
    return arr


def grid_shape(shape, name="shape"):
    """Checks a grid shape, (nz, ny, nx) or (ny, nx); returns (dim, [nx, ny, nz])."""
    try:
        shape = tuple(int(s) for s in shape)
    except TypeError:
        raise TypeError("%s must be a tuple (nz, ny, nx) or (ny, nx), got %r" % (name, shape)) from None
    if len(shape) not in (2, 3):
        raise ValueError("%s must have 2 or 3 dimensions, (ny, nx) or (nz, ny, nx); got %r" % (name, shape))
    if min(shape) < 1:
        raise ValueError("%s: every dimension must be >= 1, got %r" % (name, shape))
    if len(shape) == 3:
        return 3, [shape[2], shape[1], shape[0]]
    return 2, [shape[1], shape[0], 1]


def positive(x, name):
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        raise TypeError("%s must be a number, got %r" % (name, x))
    if not (float(x) > 0 and np.isfinite(float(x))):
        raise ValueError("%s must be a positive finite number, got %r" % (name, x))
    return float(x)


def integer(x, name, lo=None, hi=None):
    if isinstance(x, bool) or not isinstance(x, numbers.Integral):
        raise TypeError("%s must be an integer, got %r" % (name, x))
    x = int(x)
    if (lo is not None and x < lo) or (hi is not None and x > hi):
        rng = "%s..%s" % ("" if lo is None else lo, "" if hi is None else hi)
        raise ValueError("%s must be in %s, got %d" % (name, rng, x))
    return x


def real(x, name, lo=None):
    if isinstance(x, bool) or not isinstance(x, numbers.Real):
        raise TypeError("%s must be a number, got %r" % (name, x))
    x = float(x)
    if np.isnan(x) or (lo is not None and x < lo):
        raise ValueError("%s must be a number >= %s, got %r" % (name, lo, x))
    return x


def mask_array(solid, shape, name="solid"):
    """A solid mask as a C-contiguous uint8 array of `shape` (non-zero =
    solid). A C-contiguous bool or uint8 array is used as it is (bool is one
    byte, 0 or 1: no copy); anything else is converted."""
    arr = np.asarray(solid)
    if arr.shape != tuple(shape):
        raise ValueError("%s has shape %r, expected %r" % (name, arr.shape, tuple(shape)))
    if arr.dtype in (np.bool_, np.uint8) and arr.flags.c_contiguous:
        return arr.view(np.uint8)
    return np.ascontiguousarray(arr != 0, dtype=np.uint8)
