"""kdspace's file readers and writers with NumPy arrays: round trips of every format, and errors
that name the file and the row."""

import numpy as np
import pytest

import kdspace


@pytest.mark.parametrize("extension", ["fvecs", "csv", "npy"])
def test_points_round_trip(tmp_path, extension):
    points = np.random.default_rng(1).normal(size=(20, 7)).astype(np.float32)
    path = tmp_path / f"points.{extension}"
    kdspace.write_points(path, points)
    back = kdspace.read_points(path, dtype=np.float32)
    np.testing.assert_array_equal(back, points)


def test_default_dtype_follows_the_file(tmp_path):
    kdspace.write_points(tmp_path / "a.npy", np.ones((3, 2)))
    kdspace.write_points(tmp_path / "b.fvecs", np.ones((3, 2), dtype=np.float32))
    assert kdspace.read_points(tmp_path / "a.npy").dtype == np.float64
    assert kdspace.read_points(tmp_path / "b.fvecs").dtype == np.float32


def test_byte_files_read_as_bytes(tmp_path):
    values = np.random.default_rng(2).integers(0, 256, (10, 16)).astype(np.float32)
    kdspace.write_points(tmp_path / "d.bvecs", values)
    back = kdspace.read_points(tmp_path / "d.bvecs", dtype=np.uint8)
    assert back.dtype == np.uint8
    np.testing.assert_array_equal(back, values)
    kdspace.write_points(tmp_path / "e.ivecs", values)
    np.testing.assert_array_equal(kdspace.read_points(tmp_path / "e.ivecs"), values)


def test_ragged_rows_round_trip(tmp_path):
    rows = [np.arange(3), np.arange(0), np.arange(5) * 2]
    kdspace.write_rows(tmp_path / "r.ivecs", rows)
    back = kdspace.read_rows(tmp_path / "r.ivecs")
    assert [r.tolist() for r in back] == [r.tolist() for r in rows]
    kdspace.write_rows(tmp_path / "r.fvecs", [np.float32([0.5, 1.5])])
    assert kdspace.read_rows(tmp_path / "r.fvecs")[0].tolist() == [0.5, 1.5]


def test_boxes_rays_and_hits(tmp_path):
    boxes = np.float32([[0, 0, 0, 1, 1, 1], [2, 2, 2, 3, 4, 5]])
    rays = np.float32([[-1, 0.5, 0.5, 1, 0, 0]])
    kdspace.write_boxes(tmp_path / "s.boxes", boxes)
    kdspace.write_rays(tmp_path / "s.rays", rays)
    np.testing.assert_array_equal(kdspace.read_boxes(tmp_path / "s.boxes"), boxes)
    np.testing.assert_array_equal(kdspace.read_rays(tmp_path / "s.rays"), rays)
    hits = tmp_path / "s.hits"
    count = np.uint64(2).tobytes()
    hits.write_bytes(count + np.array([(0, 1.0), (-1, np.inf)], dtype=[("b", "<i4"), ("t", "<f4")]).tobytes())
    box, t = kdspace.read_hits(hits)
    assert box.tolist() == [0, -1] and t[0] == 1.0 and np.isinf(t[1])


def test_errors_name_the_file_and_the_row(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("1,2\n3,nan\n")
    with pytest.raises(ValueError, match=r"bad.csv: row 2 \(line 2\): column 2: value is not finite"):
        kdspace.read_points(bad)
    short = tmp_path / "short.fvecs"
    short.write_bytes(np.int32(4).tobytes() + np.float32([1, 2]).tobytes())
    with pytest.raises(ValueError, match=r"short.fvecs: row 1: truncated"):
        kdspace.read_points(short)
    with pytest.raises(ValueError, match="missing.fvecs"):
        kdspace.read_points(tmp_path / "missing.fvecs")
    with pytest.raises(ValueError, match="extension"):
        kdspace.read_points(tmp_path / "points.txt")
    with pytest.raises(TypeError, match="float32, float64 or uint8"):
        kdspace.read_points(tmp_path / "x.fvecs", dtype=np.int16)
