#!/usr/bin/env python3
"""Why fish fail eq. (16) in `fishtrack track` output (README, tracking
round 6).

    python3 scripts/track_failures.py HAUL OUT [HAUL OUT ...]

Matching as `fishtrack eval`: a fish frame is countable when its visible
left area >= theta_A^L (2000 px at 2048, scaled by the frame area); per
frame, boxes of tracks.csv (every row, predicted ones included) are matched
one-to-one to the truth's left boxes (Hungarian, scipy) at IoU >= 0.4 and
rows matched to non-countable fish are ignored. Each fish with a countable
frame is then, in this order: *never matched* (split by whether any
detections.csv box matches it at IoU >= 0.4), *split* (its matched frames
carry two or more track ids), *id shared* (its one track id is matched to
another fish too), *matched in < half* of its countable frames, or a
*success*. Also counts the countable fish frames no track row matches
that a detections.csv box and a stereo.csv row do match (segmented and
paired, but dropped by the tracker), and the *linking ceiling*: the fish
whose detections.csv boxes alone match them in at least half of their
countable frames, i.e. the success an ideal linker of these detections
would reach (what segmentation leaves to the tracker).
"""
import collections
import csv
import json
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment


def iou(a, b):
    iw = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    ih = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    u = a[2] * a[3] + b[2] * b[3] - iw * ih
    return iw * ih / u if u > 0 else 0


def rows_by_frame(path, box_cols, id_col=None):
    out = collections.defaultdict(list)
    with open(path) as f:
        for r in csv.reader(f):
            if not r or not r[0].lstrip("-").isdigit():
                continue
            out[int(r[0])].append((int(r[id_col]) if id_col is not None else 0,
                                   [float(r[c]) for c in box_cols]))
    return out


CEILING = "linking ceiling (fish an ideal linker of the detections would label)"


def extra(key):
    """Tally lines that are not a class of fish (no share)."""
    return key.startswith("frames") or key == CEILING


def haul(haul_dir, out_dir, tally):
    t = json.load(open(f"{haul_dir}/truth.json"))
    amin = 2000 * (t["width"] / 2048) ** 2
    truth = collections.defaultdict(list)  # frame -> [(fish, box, countable)]
    for f in t["fish"]:
        for fr in f["frames"]:
            if fr["left_box"] is not None:
                truth[fr["frame"]].append((f["id"], fr["left_box"], fr["left_area"] >= amin))
    tracks = rows_by_frame(f"{out_dir}/tracks.csv", range(2, 6), 1)
    dets = rows_by_frame(f"{out_dir}/detections.csv", range(2, 6))
    stereo = rows_by_frame(f"{out_dir}/stereo.csv", range(1, 5))

    def match(pred):
        m = {}
        for fr, tl in truth.items():
            p = pred.get(fr, [])
            if not p:
                continue
            c = np.array([[iou(q[1], x[1]) for q in p] for x in tl])
            for i, j in zip(*linear_sum_assignment(-c)):
                if c[i, j] >= 0.4 and tl[i][2]:
                    m[(fr, tl[i][0])] = p[j][0]
        return m

    mt, md, ms = match(tracks), match(dets), match(stereo)
    n = collections.Counter()
    ids = collections.defaultdict(collections.Counter)
    seg = collections.Counter()
    for fr, tl in truth.items():
        for fid, _, countable in tl:
            if not countable:
                continue
            n[fid] += 1
            seg[fid] += (fr, fid) in md
            if (fr, fid) in mt:
                ids[fid][mt[(fr, fid)]] += 1
            elif (fr, fid) in md and (fr, fid) in ms:
                tally["frames segmented and paired, in no track"] += 1
    owners = collections.defaultdict(set)
    for fid, c in ids.items():
        for tid in c:
            owners[tid].add(fid)
    for fid, k in n.items():
        if 2 * seg[fid] >= k:  # k >= 1, so at least one detection
            tally[CEILING] += 1
        c = ids.get(fid, collections.Counter())
        hits = sum(c.values())
        if hits == 0:
            why = "never matched (segmented in %s frame)" % ("no" if seg[fid] == 0 else "some")
        elif len(c) > 1:
            why = "split over several ids"
        elif len(owners[next(iter(c))]) > 1:
            why = "id shared with another fish"
        elif 2 * hits < k:
            why = "matched in < half of its frames"
        else:
            why = "success"
        tally[why] += 1


def main(argv):
    if len(argv) < 2 or len(argv) % 2:
        sys.exit(__doc__)
    tally = collections.Counter()
    for h, o in zip(argv[0::2], argv[1::2]):
        haul(h, o, tally)
    fish = sum(v for k, v in tally.items() if not extra(k))
    for k, v in sorted(tally.items(), key=lambda x: -x[1]):
        share = f"{100 * v / fish:5.1f} %" if not extra(k) else "       "
        print(f"{v:5d} {share}  {k}")


if __name__ == "__main__":
    main(sys.argv[1:])
