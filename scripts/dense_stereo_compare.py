#!/usr/bin/env python3
"""Dense-stereo baseline for FishTrack's README comparison (paper Section IV.A:
object-height blocks versus "traditional dense stereo matching").

Given a rectified left/right PNG pair and object boxes in the left view, runs
OpenCV StereoBM and StereoSGBM over the whole frame, reprojects with
cv2.reprojectImageTo3D, and measures each object's 3-D length the way
FishTrack defines it (ends along the principal axis of the object's
foreground pixels, disparity from a robust line along that axis, L = |X_H - X_T|).
Prints JSON: per method the wall time of matching and of reprojection, the
dense SAD-operation count, and per object the length (and the error when the
boxes file carries "length_mm").

usage: dense_stereo_compare.py LEFT.png RIGHT.png BOXES.json
         (--q Q.json | --geometry F CX CY CX_RIGHT BASELINE_MM)
         [--num-disparities 256] [--block 15] [--min-disparity 0] [--repeat 3]

BOXES.json: [{"id": 1, "bbox": [x, y, w, h], "length_mm": 312.0}, ...]
Q.json: a 4x4 nested list (OpenCV stereoRectify Q).
"""
import argparse
import json
import time

import cv2
import numpy as np


def q_from_geometry(f, cx, cy, cxr, b):
    tx = -b
    return np.array(
        [[1, 0, 0, -cx], [0, 1, 0, -cy], [0, 0, 0, f], [0, 0, -1.0 / tx, (cx - cxr) / tx]],
        dtype=np.float64,
    )


def object_length(left, disp, q, bbox, min_disp):
    x, y, w, h = [int(v) for v in bbox]
    roi = left[y:y + h, x:x + w]
    if roi.size == 0:
        return None
    _, fg = cv2.threshold(roi, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    ys, xs = np.nonzero(fg)
    if len(xs) < 20:
        return None
    px = np.stack([xs + x, ys + y], axis=1).astype(np.float64)
    c = px.mean(axis=0)
    cov = np.cov((px - c).T)
    evals, evecs = np.linalg.eigh(cov)
    u = evecs[:, np.argmax(evals)]
    t = (px - c) @ u
    k = 1 + len(t) // 4096
    ts = np.sort(t)
    t_lo, t_hi = ts[min(k, len(ts)) - 1], ts[-min(k, len(ts))]
    d = disp[ys + y, xs + x]
    ok = d > min_disp
    if ok.sum() < 10:
        return None
    tt, dd = t[ok], d[ok]
    # robust line d(t): least squares, drop > 3 MAD residuals, refit
    a, b0 = np.polyfit(tt, dd, 1)
    for _ in range(2):
        r = dd - (a * tt + b0)
        mad = np.median(np.abs(r - np.median(r))) * 1.4826 + 1e-6
        keep = np.abs(r) <= 3 * mad
        if keep.sum() < 10:
            break
        a, b0 = np.polyfit(tt[keep], dd[keep], 1)
    ends = []
    for te in (t_lo, t_hi):
        p = c + te * u
        hom = q @ np.array([p[0], p[1], a * te + b0, 1.0])
        if hom[3] <= 0:
            return None
        ends.append(hom[:3] / hom[3])
    return float(np.linalg.norm(ends[1] - ends[0]))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("left")
    ap.add_argument("right")
    ap.add_argument("boxes")
    ap.add_argument("--q")
    ap.add_argument("--geometry", nargs=5, type=float, metavar=("F", "CX", "CY", "CX_RIGHT", "BASELINE_MM"))
    ap.add_argument("--num-disparities", type=int, default=256)
    ap.add_argument("--block", type=int, default=15)
    ap.add_argument("--min-disparity", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    left = cv2.imread(a.left, cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(a.right, cv2.IMREAD_GRAYSCALE)
    if left is None or right is None:
        raise SystemExit(f"cannot read {a.left if left is None else a.right}")
    if a.q:
        with open(a.q) as fh:
            q = np.array(json.load(fh), dtype=np.float64)
    elif a.geometry:
        q = q_from_geometry(*a.geometry)
    else:
        raise SystemExit("give --q or --geometry")
    with open(a.boxes) as fh:
        boxes = json.load(fh)
    nd = max(16, (a.num_disparities + 15) // 16 * 16)
    blk = a.block | 1
    h, w = left.shape
    methods = {
        "StereoBM": cv2.StereoBM_create(numDisparities=nd, blockSize=blk),
        "StereoSGBM": cv2.StereoSGBM_create(
            minDisparity=a.min_disparity, numDisparities=nd, blockSize=blk,
            P1=8 * blk * blk, P2=32 * blk * blk, uniquenessRatio=5, mode=cv2.STEREO_SGBM_MODE_SGBM,
        ),
    }
    out = {"width": w, "height": h, "num_disparities": nd, "block": blk,
           # every pixel's absolute difference at every disparity, at least once
           "dense_sad_ops": w * h * nd, "methods": {}}
    for name, m in methods.items():
        if name == "StereoBM":
            m.setMinDisparity(a.min_disparity)
        best = None
        for _ in range(max(1, a.repeat)):
            t0 = time.perf_counter()
            raw = m.compute(left, right)
            t1 = time.perf_counter()
            disp = raw.astype(np.float32) / 16.0
            pts = cv2.reprojectImageTo3D(disp, q)
            t2 = time.perf_counter()
            if best is None or t1 - t0 < best[0]:
                best = (t1 - t0, t2 - t1)
        del pts
        objs = []
        for b in boxes:
            L = object_length(left, disp, q, b["bbox"], a.min_disparity)
            rec = {"id": b.get("id"), "length_mm": L}
            if L is not None and b.get("length_mm"):
                rec["error_pct"] = 100.0 * (L - b["length_mm"]) / b["length_mm"]
            objs.append(rec)
        errs = [abs(o["error_pct"]) for o in objs if "error_pct" in o]
        out["methods"][name] = {
            "match_s": best[0], "reproject_s": best[1], "objects": objs,
            "mape_pct": float(np.mean(errs)) if errs else None,
            "measured": sum(o["length_mm"] is not None for o in objs),
        }
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
