#!/usr/bin/env python3
"""Would an intensity-based coarse pass find the fish FishTrack's gradient
pass misses? A measurement for a next step, not part of the pipeline
(README, "Where FishTrack stands", session 17).

    python3 scripts/intensity_seed_probe.py K R HAUL DETECTIONS.csv [HAUL DETECTIONS.csv ...]

HAUL holds truth.json and left/NNNNNN.png; DETECTIONS.csv is `fishtrack
track`'s output for it (raw left boxes). Per left frame, the raw
(unrectified) frame is cleared of the trawl mesh, as the core does
(minimum of the openings with the main- and anti-diagonal lines of 7 px),
and box-averaged 4 x 4. A background is estimated as
`core::background` does: 16-px cell means, a grey opening by the
(2R+1)-cell square, a 3 x 3 mean, upsampled bilinearly. Components
(8-connected, at least theta_A^L / 16 reduced pixels) of `low - background
> median + K * 1.4826 * MAD` are the probe's candidate regions. Each
countable truth fish-frame (visible left area >= theta_A^L) is counted by
whether a detection matches it (IoU >= 0.4) and whether a candidate
region's box does; candidates matching no fish at IoU >= 0.1 are counted
as spurious. Needs numpy and opencv-python-headless.
"""
import collections
import csv
import json
import sys

import cv2
import numpy as np


def iou(a, b):
    iw = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    ih = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    u = a[2] * a[3] + b[2] * b[3] - iw * ih
    return iw * ih / u if u > 0 else 0


def candidates(img, k, r, area_min):
    line = np.eye(7, dtype=np.uint8)
    clean = np.minimum(cv2.morphologyEx(img, cv2.MORPH_OPEN, line),
                       cv2.morphologyEx(img, cv2.MORPH_OPEN, line[:, ::-1].copy()))
    clean = clean.astype(np.float32)
    h, w = clean.shape
    low = cv2.resize(clean, (w // 4, h // 4), interpolation=cv2.INTER_AREA)
    cells = cv2.resize(clean, (w // 16, h // 16), interpolation=cv2.INTER_AREA)
    square = cv2.getStructuringElement(cv2.MORPH_RECT, (2 * r + 1, 2 * r + 1))
    bg = cv2.blur(cv2.morphologyEx(cells, cv2.MORPH_OPEN, square), (3, 3))
    bg = cv2.resize(bg, (w // 4, h // 4), interpolation=cv2.INTER_LINEAR)
    d = low - bg
    med = np.median(d)
    sigma = 1.4826 * np.median(np.abs(d - med))
    mask = (d > med + k * sigma).astype(np.uint8)
    _, _, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    return [[x * 4, y * 4, bw * 4, bh * 4] for x, y, bw, bh, a in stats[1:]
            if a >= area_min / 16]


def main(argv):
    if len(argv) < 4 or len(argv) % 2:
        sys.exit(__doc__)
    k, r = float(argv[0]), int(argv[1])
    tally = collections.Counter()
    for haul, det_path in zip(argv[2::2], argv[3::2]):
        t = json.load(open(f"{haul}/truth.json"))
        area_min = 2000 * (t["width"] / 2048) ** 2
        dets = collections.defaultdict(list)
        with open(det_path) as f:
            for row in csv.reader(f):
                if row and row[0].lstrip("-").isdigit():
                    dets[int(row[0])].append([float(x) for x in row[2:6]])
        truth = collections.defaultdict(list)
        for fish in t["fish"]:
            for a in fish["frames"]:
                if a["left_box"] is not None and a["left_area"] >= area_min:
                    truth[a["frame"]].append(a["left_box"])
        for frame in range(1, t["frames"] + 1):
            img = cv2.imread(f"{haul}/left/{frame:06d}.png", cv2.IMREAD_GRAYSCALE)
            if img is None:
                sys.exit(f"{haul}: frame {frame}: cannot read left/{frame:06d}.png")
            comps = candidates(img, k, r, area_min)
            tally["candidate regions"] += len(comps)
            tally["spurious candidates"] += sum(
                1 for c in comps if not any(iou(c, b) >= 0.1 for b in truth[frame]))
            for b in truth[frame]:
                hit = any(iou(d, b) >= 0.4 for d in dets[frame])
                cov = any(iou(c, b) >= 0.4 for c in comps)
                tally[("detected" if hit else "missed") + (", candidate" if cov else "")] += 1
    for key, v in sorted(tally.items()):
        print(f"{v:6d}  {key}")


if __name__ == "__main__":
    main(sys.argv[1:])
