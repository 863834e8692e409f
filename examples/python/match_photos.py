#!/usr/bin/python3
"""Match the SIFT descriptors of two photographs with kdspace.KDTree and Lowe's ratio test.

OpenCV (python3-opencv) finds the keypoints of each photograph and describes each by a 128-D SIFT
descriptor (float32, kept as float32 by kdspace). The descriptors of the second photograph go into
a kdspace.KDTree; each descriptor of the first asks for its two nearest (query(k=2)), and the
match is kept when the nearest is clearly nearer than the second (Lowe's ratio test: d1 < 0.8 d2,
D. Lowe, "Distinctive image features from scale-invariant keypoints", IJCV 2004, section 7.1).

By default the photographs are the two views of the Middlebury "motorcycle" stereo pair that
scikit-image ships (Debian package python3-skimage, downloaded and unpacked on first use; see
debian_data.py). The pair is rectified: a true match lies on the same image row in both views, so
the share of matches whose rows agree within 2 pixels measures how right the matches are.

  PYTHONPATH=build/release/python /usr/bin/python3 examples/python/match_photos.py [LEFT RIGHT]
"""

import argparse
import os
import sys
import time

import cv2
import numpy as np

import kdspace

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import debian_data  # noqa: E402


def sift(path, features):
    image = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise SystemExit(f"{path}: cannot read the image")
    keypoints, descriptors = cv2.SIFT_create(nfeatures=features).detectAndCompute(image, None)
    points = np.float32([k.pt for k in keypoints]).reshape(-1, 2)
    return points, descriptors


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("photos", nargs="*", help="two photographs (default: the skimage stereo pair)")
    parser.add_argument("--features", type=int, default=0, help="keypoints per photograph (0: all OpenCV finds)")
    parser.add_argument("--ratio", type=float, default=0.8, help="Lowe's ratio (default 0.8)")
    args = parser.parse_args()
    if len(args.photos) not in (0, 2):
        parser.error("give two photographs, or none")
    left, right = args.photos or debian_data.stereo_photographs()

    started = time.perf_counter()
    left_points, left_descriptors = sift(left, args.features)
    right_points, right_descriptors = sift(right, args.features)
    print(f"SIFT: {len(left_descriptors)} and {len(right_descriptors)} descriptors of 128 values "
          f"({time.perf_counter() - started:.2f} s)")

    started = time.perf_counter()
    tree = kdspace.KDTree(right_descriptors)  # float32 stays float32
    built = time.perf_counter()
    distances, nearest = tree.query(left_descriptors, k=2, workers=-1)
    searched = time.perf_counter()
    print(f"kdspace.KDTree: built in {built - started:.3f} s, "
          f"{len(left_descriptors)} exact 2-NN queries in {searched - built:.3f} s")

    keep = distances[:, 0] < args.ratio * distances[:, 1]
    matches = np.stack([np.flatnonzero(keep), nearest[keep, 0]], axis=1)
    rows_agree = np.abs(left_points[matches[:, 0], 1] - right_points[matches[:, 1], 1]) <= 2
    print(f"Lowe's ratio test (d1 < {args.ratio} d2): {len(matches)} matches of {len(left_descriptors)}")
    print(f"matches on the same image row (within 2 px): {rows_agree.mean():.1%}")
    if not args.photos:
        # Without the ratio test, for comparison: every nearest neighbour taken as a match.
        all_rows = np.abs(left_points[:, 1] - right_points[nearest[:, 0], 1]) <= 2
        print(f"(every nearest neighbour, no ratio test: {all_rows.mean():.1%} on the same row)")


if __name__ == "__main__":
    main()
