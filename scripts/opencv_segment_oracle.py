#!/usr/bin/env python3
"""OpenCV oracle for the segmentation primitives of fishtrack-core.

Usage: opencv_segment_oracle.py DIR

Reads images written by the Rust test (host/tests/opencv_segment_oracle.rs)
from DIR and writes OpenCV's results next to them:

  grey.pgm  -> otsu.json {"otsu": t}            cv2.threshold(THRESH_OTSU)
            -> dilate/erode/gradient/open/close.pgm
                 cv2.morphologyEx with getStructuringElement(MORPH_ELLIPSE,(7,7))
            -> mesh.pgm   MORPH_OPEN with np.eye(7), then with np.fliplr(np.eye(7))
  mask.pgm  -> median.pgm  cv2.medianBlur(mask, 3)
            -> labels.bin (int32, row-major) + cc.json
                 cv2.connectedComponentsWithStats(mask, connectivity=8)
  grey.pgm + m_low.pgm + m_high.pgm
            -> backproject_<bins>.pgm for bins in 8, 16, 32:
                 H = cv2.calcHist(.., mask, [bins], [0, 256]); ratio eq. (2);
                 cv2.calcBackProject of the 0/1 histogram (H_R > 0.3), scale 255
  grey.pgm  -> lowres_<f>.bin (uint16, row-major) for f in 4, 8 when f
                 divides both sides: round(16 * cv2.resize(grey as float64,
                 (w/f, h/f), INTER_AREA)), halves up
            -> lowgrad_<f>.bin: cv2.morphologyEx of that uint16 image,
                 MORPH_GRADIENT, MORPH_ELLIPSE (5, 5)
Border conventions are OpenCV's defaults (morphology: pixels outside the
image ignored; medianBlur: replicated border).
"""
import json
import os
import sys

import cv2
import numpy as np


def read(d, name):
    img = cv2.imread(os.path.join(d, name), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise SystemExit(f"cannot read {name}")
    return img


def main():
    d = sys.argv[1]
    grey = read(d, "grey.pgm")
    t, _ = cv2.threshold(grey, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
    ell = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
    out = {
        "dilate": cv2.dilate(grey, ell),
        "erode": cv2.erode(grey, ell),
        "gradient": cv2.morphologyEx(grey, cv2.MORPH_GRADIENT, ell),
        "open": cv2.morphologyEx(grey, cv2.MORPH_OPEN, ell),
        "close": cv2.morphologyEx(grey, cv2.MORPH_CLOSE, ell),
    }
    main_diag = np.eye(7, dtype=np.uint8)
    anti_diag = np.fliplr(main_diag).copy()
    out["mesh"] = cv2.morphologyEx(
        cv2.morphologyEx(grey, cv2.MORPH_OPEN, main_diag), cv2.MORPH_OPEN, anti_diag
    )
    mask = read(d, "mask.pgm")
    out["median"] = cv2.medianBlur(mask, 3)
    for k, v in out.items():
        cv2.imwrite(os.path.join(d, k + ".pgm"), v)
    n, labels, stats, centroids = cv2.connectedComponentsWithStats(
        mask, connectivity=8, ltype=cv2.CV_32S
    )
    labels.astype("<i4").tofile(os.path.join(d, "labels.bin"))
    cc = [
        {
            "left": int(s[cv2.CC_STAT_LEFT]),
            "top": int(s[cv2.CC_STAT_TOP]),
            "width": int(s[cv2.CC_STAT_WIDTH]),
            "height": int(s[cv2.CC_STAT_HEIGHT]),
            "area": int(s[cv2.CC_STAT_AREA]),
            "cx": float(c[0]),
            "cy": float(c[1]),
        }
        for s, c in zip(stats[1:], centroids[1:])
    ]
    m_low = read(d, "m_low.pgm")
    m_high = read(d, "m_high.pgm")
    for bins in (8, 16, 32):
        hl = cv2.calcHist([grey], [0], m_low, [bins], [0, 256]).ravel()
        hh = cv2.calcHist([grey], [0], m_high, [bins], [0, 256]).ravel()
        ratio = np.where(hl > 0, np.minimum(hh / np.maximum(hl, 1), 1.0), 0.0)
        keep = (ratio > np.float32(0.3)).astype(np.float32)
        bp = cv2.calcBackProject([grey], [0], keep.reshape(-1, 1), [0, 256], 255)
        cv2.imwrite(os.path.join(d, f"backproject_{bins}.pgm"), bp)
    h, w = grey.shape
    ell5 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    for f in (4, 8):
        if w % f or h % f:
            continue
        mean = cv2.resize(grey.astype(np.float64), (w // f, h // f), interpolation=cv2.INTER_AREA)
        low = np.floor(16.0 * mean + 0.5).astype(np.uint16)
        low.astype("<u2").tofile(os.path.join(d, f"lowres_{f}.bin"))
        grad = cv2.morphologyEx(low, cv2.MORPH_GRADIENT, ell5)
        grad.astype("<u2").tofile(os.path.join(d, f"lowgrad_{f}.bin"))
    with open(os.path.join(d, "otsu.json"), "w") as f:
        json.dump({"otsu": int(t), "components": n - 1, "cc": cc}, f)


if __name__ == "__main__":
    main()
