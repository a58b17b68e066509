#!/usr/bin/env python3
"""The FishTrack segmentation pipeline done "the OpenCV way", timed.

    bench/compare_opencv.py HAUL [--repeats N] [--json]

For every stereo pair of HAUL, both frames: cv2.imread (grey), remap with
the haul's calibration (cv2.stereoRectify CALIB_ZERO_DISPARITY alpha 0,
cv2.initUndistortRectifyMap, CV_16SC2 fixed-point maps, INTER_LINEAR),
trawl-mesh removal (grey openings by the 7-pixel main-diagonal line, then by
the anti-diagonal line), 7 x 7 elliptic morphological gradient, a global
threshold on the gradient (median + 4 MAD, FishTrack's rule; Otsu with
--otsu), cv2.connectedComponentsWithStats, and per object of at least
area_min / 4 pixels the local processing of Section III: ROI of the
enlarged box, Otsu, the two shifted thresholds of eq. (1), 3 x 3 median,
histogram backprojection of the ratio histogram (eq. (2)-(3)), area and
variance rejection, closing and opening with the 7 x 7 ellipse and the
final connectedComponentsWithStats. Stereo matching and tracking are not
included (they are a small share of FishTrack's time).

Timed: the whole haul from reading calibration.yml to the last pair, as
`fishtrack track` is timed by scripts/bench_vs_opencv.sh; the median of
--repeats runs. OpenCV uses its default thread count.
"""
import argparse
import json
import os
import sys
import time

import cv2
import numpy as np


def natural_key(name):
    import re
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", name)]


def load_calibration(path):
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
    if not fs.isOpened():
        sys.exit(f"{path}: cannot open calibration")

    def mat(*names):
        for n in names:
            node = fs.getNode(n)
            if not node.empty():
                return node.mat()
        sys.exit(f"{path}: missing {names[0]}")

    m1 = mat("M1", "cameraMatrixL", "cameraMatrix1")
    d1 = mat("D1", "distCoeffsL", "distCoeffs1")
    m2 = mat("M2", "cameraMatrixR", "cameraMatrix2")
    d2 = mat("D2", "distCoeffsR", "distCoeffs2")
    r = mat("R")
    t = mat("T")
    w = int(fs.getNode("image_width").real())
    h = int(fs.getNode("image_height").real())
    return m1, d1, m2, d2, r, t, (w, h)


def local_region(img, x, y, w, h, area_min, ellipse, var_min=30.0, bins=16):
    """Section III.A-D on one enlarged component box (OpenCV calls)."""
    H, W = img.shape
    cx, cy = x + w / 2.0, y + h / 2.0
    x0, x1 = int(max(0, cx - 0.75 * w)), int(min(W, cx + 0.75 * w + 1))
    y0, y1 = int(max(0, cy - 0.75 * h)), int(min(H, cy + 0.75 * h + 1))
    roi = img[y0:y1, x0:x1]
    if roi.size < area_min:
        return 0
    tau, _ = cv2.threshold(roi, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    low = roi[roi <= tau]
    mu = float(low.mean()) if low.size else tau
    t_low, t_high = int(tau - 1.0 * (tau - mu)), int(tau - 0.7 * (tau - mu))
    _, m_low = cv2.threshold(roi, t_low, 255, cv2.THRESH_BINARY)
    _, m_high = cv2.threshold(roi, t_high, 255, cv2.THRESH_BINARY)
    m_low = cv2.medianBlur(m_low, 3)
    m_high = cv2.medianBlur(m_high, 3)
    h_low = cv2.calcHist([roi], [0], m_low, [bins], [0, 256])
    h_high = cv2.calcHist([roi], [0], m_high, [bins], [0, 256])
    ratio = np.where(h_low > 0, np.minimum(h_high / np.maximum(h_low, 1), 1.0), 0.0)
    bp = cv2.calcBackProject([roi], [0], (ratio * 255).astype(np.float32), [0, 256], 1)
    _, b = cv2.threshold(bp.astype(np.uint8), int(0.3 * 255), 255, cv2.THRESH_BINARY)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(b, connectivity=8)
    keep = np.zeros(n, np.uint8)
    for i in range(1, n):
        if stats[i, cv2.CC_STAT_AREA] >= area_min:
            vals = roi[labels == i]
            if vals.var(ddof=1) >= var_min:
                keep[i] = 255
    b = keep[labels]
    b = cv2.morphologyEx(b, cv2.MORPH_CLOSE, ellipse)
    b = cv2.morphologyEx(b, cv2.MORPH_OPEN, ellipse)
    n, _, stats, _ = cv2.connectedComponentsWithStats(b, connectivity=8)
    return int(np.sum(stats[1:, cv2.CC_STAT_AREA] >= area_min))


def mad_threshold(grad):
    hist = np.bincount(grad.ravel(), minlength=256)
    cum = np.cumsum(hist)
    half = (cum[-1] + 1) // 2
    med = int(np.searchsorted(cum, half))
    dev = np.zeros(256, np.int64)
    for i, c in enumerate(hist):
        dev[abs(i - med)] += c
    mad = max(int(np.searchsorted(np.cumsum(dev), half)), 1)
    return min(med + 4 * mad, 255)


def segment(img, area_min, use_otsu):
    main = np.eye(7, dtype=np.uint8)
    anti = np.fliplr(main).copy()
    f = cv2.morphologyEx(img, cv2.MORPH_OPEN, main)
    f = cv2.morphologyEx(f, cv2.MORPH_OPEN, anti)
    ellipse = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
    grad = cv2.morphologyEx(f, cv2.MORPH_GRADIENT, ellipse)
    if use_otsu:
        _, fg = cv2.threshold(grad, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    else:
        _, fg = cv2.threshold(grad, mad_threshold(grad), 255, cv2.THRESH_BINARY)
    n, _, stats, _ = cv2.connectedComponentsWithStats(fg, connectivity=8)
    objects = 0
    for i in range(1, n):
        x, y, w, h, a = stats[i]
        if a >= area_min // 4:
            objects += local_region(f, x, y, w, h, area_min, ellipse)
    return objects


def run_haul(haul, use_otsu):
    m1, d1, m2, d2, r, t, size = load_calibration(os.path.join(haul, "calibration.yml"))
    r1, r2, p1, p2, q, _, _ = cv2.stereoRectify(
        m1, d1, m2, d2, size, r, t, flags=cv2.CALIB_ZERO_DISPARITY, alpha=0
    )
    maps = [
        cv2.initUndistortRectifyMap(m1, d1, r1, p1, size, cv2.CV_16SC2),
        cv2.initUndistortRectifyMap(m2, d2, r2, p2, size, cv2.CV_16SC2),
    ]
    area_min = int(round(2000 * (size[0] / 2048.0) ** 2))
    names = sorted(
        (n for n in os.listdir(os.path.join(haul, "left")) if n.lower().endswith(".png")),
        key=natural_key,
    )
    objects = 0
    for name in names:
        for side, (mx, my) in zip(("left", "right"), maps):
            raw = cv2.imread(os.path.join(haul, side, name), cv2.IMREAD_GRAYSCALE)
            if raw is None:
                sys.exit(f"{os.path.join(haul, side, name)}: cannot read")
            rect = cv2.remap(raw, mx, my, cv2.INTER_LINEAR)
            objects += segment(rect, area_min, use_otsu)
    return len(names), objects


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("haul")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--otsu", action="store_true", help="Otsu on the gradient instead of median + 4 MAD")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    times = []
    for _ in range(max(a.repeats, 1)):
        t0 = time.perf_counter()
        pairs, objects = run_haul(a.haul, a.otsu)
        times.append(time.perf_counter() - t0)
    times.sort()
    med = times[len(times) // 2]
    out = {
        "haul": a.haul,
        "pairs": pairs,
        "objects": objects,
        "seconds": med,
        "ms_per_pair": 1e3 * med / max(pairs, 1),
        "pairs_per_s": pairs / med if med > 0 else 0.0,
        "opencv": cv2.__version__,
        "threads": cv2.getNumThreads(),
        "repeats": len(times),
    }
    if a.json:
        print(json.dumps(out))
    else:
        print(
            f"OpenCV {out['opencv']} ({out['threads']} threads): {pairs} pairs, "
            f"{out['ms_per_pair']:.1f} ms/pair, {out['pairs_per_s']:.2f} pairs/s "
            f"(median of {out['repeats']}; {objects} objects)"
        )


if __name__ == "__main__":
    main()
