#!/usr/bin/env python3
"""Where issue 5's per-fish lengths are lost, and what the length gates
withhold (README, "Where FishTrack stands", session 17).

    FISHTRACK_STEREO_DIAG=1 fishtrack track HAUL --out OUT
    python3 scripts/length_accounting.py HAUL OUT [HAUL OUT ...]

HAUL is a `fishtrack synth` haul (truth.json); OUT a `fishtrack track`
output written with FISHTRACK_STEREO_DIAG set (it adds stereo_diag.csv:
every stereo pair with its length, measured or withheld, and the end
gates' inputs).

Part 1, per *measurable* fish (wholly inside both views in some frame, as
`fishtrack eval` counts them): the fish is *measured* when its majority
track (tracks.csv boxes matched one-to-one to the truth's left boxes by
the optimal assignment on 1 - IoU with IoU >= 0.4, countable frames or
not, the smallest id on a tie: as eval) has a length in fish.csv. Otherwise, in
this order: *no track*; *not segmented* (no detections.csv box matches any
of its wholly-inside frames); *not paired* (no stereo.csv row does);
*paired, every length withheld* (the stereo rows of those frames carry no
length); or *paired with a length, track has none*.

Part 2, per stereo pair the length stage measured (stereo_diag.csv
`measured` = 1) whose left box matches a truth fish at IoU >= 0.4: the
relative length error against the fish's `length_mm`, pooled by what the
gates decided — *kept* (consistent), *withheld: mask ends disagree*
(`max_end_disagreement`: an end's mask disparity departs from the block
line by more than 4 % of it), *withheld: end touches another object*
(the occlusion gate) or both — and, for the pairs that touch nothing, by
the larger end disagreement (the gate's input).
"""
import collections
import csv
import json
import statistics
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment


def iou(a, b):
    iw = max(0, min(a[0] + a[2], b[0] + b[2]) - max(a[0], b[0]))
    ih = max(0, min(a[1] + a[3], b[1] + b[3]) - max(a[1], b[1]))
    u = a[2] * a[3] + b[2] * b[3] - iw * ih
    return iw * ih / u if u > 0 else 0


# stereo.csv's length_mm column: frame, left box (4), right box (4), head
# x, y, z, tail x, y, z, length_mm (DESIGN.md); empty when not measured
STEREO_LENGTH = 15


def boxes_by_frame(path, box_cols, id_col=None):
    """Rows by frame as (id or 0, box, row); header and comment lines,
    whose first field is no frame number, are skipped."""
    out = collections.defaultdict(list)
    with open(path) as f:
        for r in csv.reader(f):
            if not r or not r[0].lstrip("-").isdigit():
                continue
            out[int(r[0])].append((int(r[id_col]) if id_col is not None else 0,
                                   [float(r[c]) for c in box_cols], r))
    return out


def number(v, default):
    try:
        x = float(v)
    except ValueError:
        return default
    return default if x != x else x


def haul(haul_dir, out_dir, fish_tally, gate_errors, dev_errors):
    t = json.load(open(f"{haul_dir}/truth.json"))
    truth = collections.defaultdict(list)  # frame -> [(fish index, frame record)]
    for k, f in enumerate(t["fish"]):
        for a in f["frames"]:
            if a["left_box"] is not None:
                truth[a["frame"]].append((k, a))
    tracks = boxes_by_frame(f"{out_dir}/tracks.csv", range(2, 6), 1)
    dets = boxes_by_frame(f"{out_dir}/detections.csv", range(2, 6))
    stereo = boxes_by_frame(f"{out_dir}/stereo.csv", range(1, 5))
    lengths = {}
    with open(f"{out_dir}/fish.csv") as f:
        for r in csv.DictReader(f):
            lengths[int(r["track_id"])] = r["length_mm"] != ""

    # tracks.csv rows matched to the truth one-to-one per frame (as eval)
    ids = collections.defaultdict(collections.Counter)
    for fr, tl in truth.items():
        p = tracks.get(fr, [])
        if not p:
            continue
        c = np.array([[iou(q[1], a["left_box"]) for q in p] for _, a in tl])
        # eval's (motmetrics') cost: 1 - IoU, pairs under IoU 0.4 forbidden
        cost = np.where(c >= 0.4, 1.0 - c, 1e6)
        for i, j in zip(*linear_sum_assignment(cost)):
            if c[i, j] >= 0.4:
                ids[tl[i][0]][p[j][0]] += 1

    def any_match(rows, box, need_length=False):
        return any(iou(b, box) >= 0.4 and (not need_length or r[STEREO_LENGTH] != "")
                   for _, b, r in rows)

    for k, f in enumerate(t["fish"]):
        inside = [a for a in f["frames"]
                  if a["inside_left"] and a["inside_right"] and a["left_box"] is not None]
        if not inside:
            continue
        if not ids[k]:
            why = "no track"
        else:
            # the majority track, the smallest id on a tie (as eval)
            track = min(ids[k], key=lambda i: (-ids[k][i], i))
            if lengths.get(track):
                why = "measured"
            elif not any(any_match(dets[a["frame"]], a["left_box"]) for a in inside):
                why = "track; not segmented in its inside frames"
            elif not any(any_match(stereo[a["frame"]], a["left_box"]) for a in inside):
                why = "track; segmented, not paired"
            elif not any(any_match(stereo[a["frame"]], a["left_box"], True) for a in inside):
                why = "track; paired, every length withheld"
            else:
                why = "track; paired with a length, track has none"
        fish_tally[why] += 1

    with open(f"{out_dir}/stereo_diag.csv") as fh:
        for r in csv.DictReader(fh):
            if r["measured"] != "1":
                continue
            lb = [float(r[c]) for c in ("lx", "ly", "lw", "lh")]
            cands = truth.get(int(r["frame"]), [])
            best = max(cands, key=lambda ka: iou(ka[1]["left_box"], lb), default=None)
            if best is None or iou(best[1]["left_box"], lb) < 0.4:
                continue
            true_mm = t["fish"][best[0]]["length_mm"]
            err = 100 * abs(float(r["length_mm"]) - true_mm) / true_mm
            touch = r["e0_touch"] == "1" or r["e1_touch"] == "1"
            dev = max(number(r["e0_dev"], float("inf")), number(r["e1_dev"], float("inf")))
            if r["consistent"] == "1":
                gate = "kept"
            elif touch and dev <= 0.04:
                gate = "withheld: end touches another object"
            elif touch:
                gate = "withheld: both"
            else:
                gate = "withheld: mask ends disagree"
            gate_errors[gate].append(err)
            if not touch:
                edge = next((e for e in (0.01, 0.02, 0.03, 0.04, 0.06, 0.1, 0.2) if dev <= e),
                            float("inf"))
                dev_errors[edge].append(err)


def row(name, errs):
    if not errs:
        return f"{name:40s} {0:5d}"
    big = sum(e > 10 for e in errs)
    return (f"{name:40s} {len(errs):5d}  MAPE {sum(errs) / len(errs):6.2f} %  "
            f"median {statistics.median(errs):5.2f} %  > 10 %: {big}")


def main(argv):
    if len(argv) < 2 or len(argv) % 2:
        sys.exit(__doc__)
    fish_tally = collections.Counter()
    gate_errors = collections.defaultdict(list)
    dev_errors = collections.defaultdict(list)
    for h, o in zip(argv[0::2], argv[1::2]):
        haul(h, o, fish_tally, gate_errors, dev_errors)
    n = sum(fish_tally.values())
    print(f"measurable fish: {n}")
    for k, v in fish_tally.most_common():
        print(f"{v:5d} {100 * v / max(n, 1):5.1f} %  {k}")
    print("\nmeasured stereo pairs matched to a fish: length error by gate")
    for k in sorted(gate_errors):
        print(row(k, gate_errors[k]))
    print("\npairs touching no other object: by the larger end disagreement")
    for e in sorted(dev_errors):
        print(row(f"<= {e:g}" if e != float("inf") else "> 0.2 or none", dev_errors[e]))


if __name__ == "__main__":
    main(sys.argv[1:])
