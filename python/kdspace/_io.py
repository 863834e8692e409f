"""The file formats of kdspace as NumPy arrays: .fvecs .ivecs .bvecs .csv .npy (points, chosen by
the extension), ragged result rows (.ivecs/.fvecs), .boxes, .rays and .hits. Errors name the file
and the row (ValueError)."""

import os

import numpy as np

from . import _core

__all__ = ["read_points", "write_points", "read_rows", "write_rows", "read_boxes", "write_boxes",
           "read_rays", "write_rays", "read_hits"]


def read_points(path, dtype=None):
    """Points, one per row, as an (n, dim) array. dtype: float32, float64 or uint8 (every value an
    integer 0..255, as in .bvecs files); by default float64 for .csv and float64 .npy files,
    float32 otherwise. Every value must be finite and every row of the same length."""
    path = os.fspath(path)
    if dtype is None:
        dtype = np.float64 if _core.stores_double(path) else np.float32
    dtype = np.dtype(dtype)
    readers = {np.dtype(np.float32): _core.read_points_float32, np.dtype(np.float64): _core.read_points_float64,
               np.dtype(np.uint8): _core.read_points_uint8}
    if dtype not in readers:
        raise TypeError(f"read_points reads float32, float64 or uint8, not {dtype}")
    return readers[dtype](path)


def write_points(path, points):
    """Writes an (n, dim) array in the format of the extension (.fvecs .ivecs .bvecs .csv .npy),
    through a temporary file renamed into place."""
    array = np.asarray(points)
    if array.dtype.kind not in "biuf":
        raise TypeError(f"points must hold real numbers, not {array.dtype}")
    if array.dtype == np.float32:
        _core.write_points_float32(os.fspath(path), np.ascontiguousarray(array))
    else:
        _core.write_points_float64(os.fspath(path), np.ascontiguousarray(array, dtype=np.float64))


def read_rows(path):
    """Rows of different lengths (radius search results) from .ivecs (int32) or .fvecs (float32):
    a list of 1-D arrays."""
    path = os.fspath(path)
    if path.lower().endswith(".ivecs"):
        return _core.read_ivecs_rows(path)
    if path.lower().endswith(".fvecs"):
        return _core.read_fvecs_rows(path)
    raise ValueError(f"{path}: ragged rows are read from .ivecs or .fvecs files")


def write_rows(path, rows):
    """Writes rows of different lengths as .ivecs (int32) or .fvecs (float32)."""
    path = os.fspath(path)
    if path.lower().endswith(".ivecs"):
        _core.write_ivecs_rows(path, [np.ascontiguousarray(r, dtype=np.int32) for r in rows])
    elif path.lower().endswith(".fvecs"):
        _core.write_fvecs_rows(path, [np.ascontiguousarray(r, dtype=np.float32) for r in rows])
    else:
        raise ValueError(f"{path}: ragged rows are written to .ivecs or .fvecs files")


def read_boxes(path):
    """A .boxes file as an (n, 6) float32 array: min x, min y, min z, max x, max y, max z."""
    return _core.read_boxes(os.fspath(path))


def write_boxes(path, boxes):
    _core.write_boxes(os.fspath(path), np.ascontiguousarray(np.asarray(boxes).reshape(-1, 6), dtype=np.float32))


def read_rays(path):
    """A .rays file as an (n, 6) float32 array: origin x y z, direction x y z."""
    return _core.read_rays(os.fspath(path))


def write_rays(path, rays):
    _core.write_rays(os.fspath(path), np.ascontiguousarray(np.asarray(rays).reshape(-1, 6), dtype=np.float32))


def read_hits(path):
    """A .hits file as (box, t): box index (-1 for a miss) and ray parameter (inf for a miss)."""
    boxes, t = _core.read_hits(os.fspath(path))
    return boxes.astype(np.intp, copy=False), t
