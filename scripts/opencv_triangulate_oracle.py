#!/usr/bin/env python3
"""OpenCV oracle for FishTrack's stereo triangulation (paper Section IV.D.2).

Reads JSON on stdin:
  {"f": .., "cx": .., "cy": .., "cx_right": .., "baseline": .., "width": W, "height": H,
   "points": [[x, y, d], ...]}            # x, y integer pixels of the left view
and writes JSON on stdout:
  {"P1": 3x4, "P2": 3x4, "Q": 4x4,        # the rectified pair, OpenCV convention
   "rectify": {"P1", "P2", "Q"},          # cv2.stereoRectify on the equivalent raw pair
   "triangulate": [[X, Y, Z], ...],       # cv2.triangulatePoints (float64), dehomogenised
   "reproject":   [[X, Y, Z], ...]}       # cv2.reprojectImageTo3D (float32 disparity map)

The right camera sits at +baseline along x (T = [-baseline, 0, 0], the
stereoCalibrate convention X_right = R X_left + T), disparity d = x_left - x_right.
"""
import json
import sys

import cv2
import numpy as np


def main():
    cfg = json.load(sys.stdin)
    f, cx, cy = float(cfg["f"]), float(cfg["cx"]), float(cfg["cy"])
    cxr, b = float(cfg["cx_right"]), float(cfg["baseline"])
    w, h = int(cfg["width"]), int(cfg["height"])
    pts = np.array(cfg["points"], dtype=np.float64).reshape(-1, 3)

    p1 = np.array([[f, 0, cx, 0], [0, f, cy, 0], [0, 0, 1, 0]], dtype=np.float64)
    p2 = np.array([[f, 0, cxr, -f * b], [0, f, cy, 0], [0, 0, 1, 0]], dtype=np.float64)
    tx = -b
    q = np.array(
        [[1, 0, 0, -cx], [0, 1, 0, -cy], [0, 0, 0, f], [0, 0, -1.0 / tx, (cx - cxr) / tx]],
        dtype=np.float64,
    )

    # cv2.stereoRectify on an undistorted, already parallel pair must give the same form
    k = np.array([[f, 0, cx], [0, f, cy], [0, 0, 1]], dtype=np.float64)
    r1, r2, rp1, rp2, rq, _, _ = cv2.stereoRectify(
        k, np.zeros((1, 5)), k, np.zeros((1, 5)), (w, h), np.eye(3), np.array([[tx], [0.0], [0.0]]),
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=-1,
    )

    left = np.ascontiguousarray(pts[:, :2].T)
    right = np.ascontiguousarray(np.stack([pts[:, 0] - pts[:, 2], pts[:, 1]]))
    hom = cv2.triangulatePoints(p1, p2, left, right)
    tri = (hom[:3] / hom[3]).T

    disp = np.zeros((h, w), dtype=np.float32)
    for x, y, d in pts:
        disp[int(y), int(x)] = d
    img3 = cv2.reprojectImageTo3D(disp, q.astype(np.float64), handleMissingValues=False)
    rep = np.array([img3[int(y), int(x)] for x, y, _ in pts], dtype=np.float64)

    json.dump(
        {
            "P1": p1.tolist(),
            "P2": p2.tolist(),
            "Q": q.tolist(),
            "rectify": {"P1": rp1.tolist(), "P2": rp2.tolist(), "Q": rq.tolist()},
            "triangulate": tri.tolist(),
            "reproject": rep.tolist(),
        },
        sys.stdout,
    )


if __name__ == "__main__":
    main()
