#!/usr/bin/env python3
"""Classify the segmentation misses of FishTrack's `detections.csv` (issue 4).

Usage:
    seg_misses.py [--alpha A] HAUL DETECTIONS.csv [HAUL DETECTIONS.csv ...]

HAUL is a `fishtrack synth` haul (truth.json, calibration.yml, left/NNNNNN.png).

For every countable truth fish-frame (visible left area >= theta_A^L scaled
to the frame) that no detection matches at IoU >= 0.4, prints its class:

- outside view: more than half of the truth box lies outside the raw pixels
  that the rectified left view sees (cv2.stereoRectify with
  CALIB_ZERO_DISPARITY and alpha A, default 0.25 as FishTrack rectifies),
  i.e. the crop;
- hit if clipped: a detection matches the truth box clipped to that view;
- cut by frame: visible fraction < 0.5 (object / no object);
- touching / isolated (another truth box intersects or not), with an object
  at IoU 0.1-0.4 or no object; touching fish with an object are split into
  merged (the object covers this fish and more than half of a neighbour),
  the neighbour (the object matches the neighbour), fragment.

and a table of hits and miss classes by contrast (80th percentile inside the
truth box minus the median of a 30-px ring around it), to show which misses
are dim fish. Needs python3 with cv2 and numpy.
"""
import csv
import json
import sys
from collections import Counter, defaultdict

import cv2
import numpy as np


def iou(a, b):
    ax0, ay0, aw, ah = a
    bx0, by0, bw, bh = b
    ix = max(0, min(ax0 + aw, bx0 + bw) - max(ax0, bx0))
    iy = max(0, min(ay0 + ah, by0 + bh) - max(ay0, by0))
    i = ix * iy
    return i / (aw * ah + bw * bh - i + 1e-9)


def cover(a, b):
    """Fraction of box a inside box b."""
    ax0, ay0, aw, ah = a
    bx0, by0, bw, bh = b
    ix = max(0, min(ax0 + aw, bx0 + bw) - max(ax0, bx0))
    iy = max(0, min(ay0 + ah, by0 + bh) - max(ay0, by0))
    return ix * iy / (aw * ah + 1e-9)


def rectified_view_mask(haul, alpha):
    """Raw left pixels that the rectified left view samples."""
    fs = cv2.FileStorage(f"{haul}/calibration.yml", cv2.FILE_STORAGE_READ)
    g = lambda k: fs.getNode(k).mat()
    w, h = int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real())
    r1, _, p1, _, _, _, _ = cv2.stereoRectify(
        g("M1"), g("D1"), g("M2"), g("D2"), (w, h), g("R"), g("T"),
        flags=cv2.CALIB_ZERO_DISPARITY, alpha=alpha)
    mx, my = cv2.initUndistortRectifyMap(g("M1"), g("D1"), r1, p1, (w, h), cv2.CV_32FC1)
    border = np.concatenate([
        np.stack([mx[0], my[0]], 1),
        np.stack([mx[:, -1], my[:, -1]], 1),
        np.stack([mx[-1][::-1], my[-1][::-1]], 1),
        np.stack([mx[::-1, 0], my[::-1, 0]], 1)])
    m = np.zeros((h, w), np.uint8)
    cv2.fillPoly(m, [np.round(border).astype(np.int32)], 1)
    return m


def contrast(img, b):
    x, y, w, h = [int(v) for v in b]
    x, y = max(0, x), max(0, y)
    inner = img[y:y + h, x:x + w].astype(float)
    ring = np.concatenate([
        img[max(0, y - 30):y, x:x + w].ravel(), img[y + h:y + h + 30, x:x + w].ravel(),
        img[y:y + h, max(0, x - 30):x].ravel(), img[y:y + h, x + w:x + w + 30].ravel()]).astype(float)
    if inner.size == 0:
        return 0.0
    return float(np.percentile(inner, 80) - (np.median(ring) if ring.size else 0))


def main(args):
    alpha = 0.25
    if args[:1] == ["--alpha"] and len(args) > 1:
        alpha = float(args[1])
        args = args[2:]
    if len(args) < 2 or len(args) % 2:
        sys.exit(__doc__)
    classes = Counter()
    by_contrast = defaultdict(Counter)
    buckets = ["<10", "10-20", "20-40", ">=40"]
    for haul, det in zip(args[0::2], args[1::2]):
        t = json.load(open(f"{haul}/truth.json"))
        amin = 2000 * (t["width"] / 2048) ** 2
        view = rectified_view_mask(haul, alpha)
        dets = defaultdict(list)
        for r in csv.reader(open(det)):
            dets[int(r[0])].append([float(v) for v in r[2:6]])
        boxes = defaultdict(list)
        for f in t["fish"]:
            for fr in f["frames"]:
                if fr.get("left_box"):
                    boxes[fr["frame"]].append((f["id"], fr["left_box"]))
        imgs = {}
        for f in t["fish"]:
            for fr in f["frames"]:
                b = fr.get("left_box")
                if not b or fr["left_area"] < amin:
                    continue
                n = fr["frame"]
                ds = dets[n]
                best = max([iou(b, d) for d in ds] + [0])
                if best >= 0.4:
                    k = "hit"
                else:
                    x, y, w, h = [int(v) for v in b]
                    sub = view[max(0, y):y + h, max(0, x):x + w]
                    ys, xs = np.nonzero(sub)
                    clipped = ([xs.min() + max(0, x), ys.min() + max(0, y),
                                xs.max() - xs.min() + 1, ys.max() - ys.min() + 1]
                               if len(xs) else [0, 0, 0, 0])
                    others = [ob for fid, ob in boxes[n] if fid != f["id"]]
                    if sub.size == 0 or sub.mean() < 0.5:
                        k = "outside the rectified view"
                    elif max([iou(clipped, d) for d in ds] + [0]) >= 0.4:
                        k = "hit if truth clipped to the view"
                    elif fr["left_visible_fraction"] < 0.5:
                        k = "cut by frame, " + ("object" if best > 0.1 else "no object")
                    elif not any(iou(b, ob) > 0 for ob in others):
                        k = "isolated, " + ("object IoU 0.1-0.4" if best > 0.1 else "no object")
                    elif best <= 0.1:
                        k = "touching, no object"
                    else:
                        d = max(ds, key=lambda d: iou(b, d))
                        if cover(b, d) > 0.6 and any(cover(ob, d) > 0.5 for ob in others):
                            k = "touching, merged with a neighbour"
                        elif any(iou(ob, d) >= 0.4 for ob in others):
                            k = "touching, object is the neighbour"
                        else:
                            k = "touching, fragment"
                    print(f"{haul},{n},{f['id']},{k},{best:.2f}")
                classes[k] += 1
                if n not in imgs:
                    imgs = {n: cv2.imread(f"{haul}/left/{n:06d}.png", 0)}
                c = contrast(imgs[n], b)
                by_contrast[k][buckets[(c >= 10) + (c >= 20) + (c >= 40)]] += 1
    total = sum(classes.values())
    print(f"\n{'class':40s} {'n':>5s} {'share':>6s}" + "".join(f"{b:>7s}" for b in buckets))
    for k, v in classes.most_common():
        print(f"{k:40s} {v:5d} {v / total:6.1%}" + "".join(f"{by_contrast[k][b]:7d}" for b in buckets))


if __name__ == "__main__":
    main(sys.argv[1:])
