#!/usr/bin/env python3
"""Which end disparity is wrong where the length gate withholds a pair
(README, "Where FishTrack stands", session 30).

    FISHTRACK_STEREO_DIAG=1 fishtrack track HAUL --out OUT
    python3 scripts/end_disparity_errors.py HAUL OUT [HAUL OUT ...]

For every measured stereo pair of OUT/stereo_diag.csv whose left box
matches a truth fish at IoU >= 0.4, touches no other object, and whose
left and right boxes are both within 7 % (box diagonal) of the truth's
(whole masks: no merge, no cut), each end's disparity is compared with
the truth's: f·B/z of the nearer of the fish's head and tail (f·B from
the row's own end disparity and depth). Printed per group (consistent or
not; the end's mask-vs-line deviation above the 4 % of session 29 or not):
the masks' own end disparity error and, where the line's value was used
(the masks more than `mask_end_tolerance` from it), the line's error.
"""
import collections
import csv
import json
import statistics
import sys

from length_accounting import iou


def main(argv):
    if len(argv) < 2 or len(argv) % 2:
        sys.exit(__doc__)
    out = collections.defaultdict(list)
    for haul, res in zip(argv[0::2], argv[1::2]):
        t = json.load(open(f"{haul}/truth.json"))
        truth = collections.defaultdict(list)
        for k, f in enumerate(t["fish"]):
            for a in f["frames"]:
                if a["left_box"] is not None:
                    truth[a["frame"]].append((k, a))
        for r in csv.DictReader(open(f"{res}/stereo_diag.csv")):
            if r["measured"] != "1" or r["e0_touch"] == "1" or r["e1_touch"] == "1":
                continue
            lb = [float(r[c]) for c in ("lx", "ly", "lw", "lh")]
            rb = [float(r[c]) for c in ("rx", "ry", "rw", "rh")]
            cands = truth.get(int(r["frame"]), [])
            best = max(cands, key=lambda ka: iou(ka[1]["left_box"], lb), default=None)
            if best is None or iou(best[1]["left_box"], lb) < 0.4 or not best[1]["right_box"]:
                continue
            a = best[1]

            def ratio(b, tb):
                return ((b[2] ** 2 + b[3] ** 2) / (tb[2] ** 2 + tb[3] ** 2)) ** 0.5

            if abs(ratio(lb, a["left_box"]) - 1) > 0.07 or abs(ratio(rb, a["right_box"]) - 1) > 0.07:
                continue
            fb = float(r["e0_d"]) * float(r["e0_z"])
            for e in ("e0", "e1"):
                px = (float(r[e + "_px"]), float(r[e + "_py"]))
                dh = (px[0] - a["head_px_left"][0]) ** 2 + (px[1] - a["head_px_left"][1]) ** 2
                dt = (px[0] - a["tail_px_left"][0]) ** 2 + (px[1] - a["tail_px_left"][1]) ** 2
                d_true = fb / (a["head_mm"][2] if dh < dt else a["tail_mm"][2])
                mask_d, used, dev = float(r[e + "_mask_d"]), float(r[e + "_d"]), float(r[e + "_dev"])
                line = used if abs(used - mask_d) > 1e-3 else None
                key = (f"consistent={r['consistent']}", f"deviation>4%={dev > 0.04}")
                out[key].append((abs(mask_d - d_true), None if line is None else abs(line - d_true)))
    for k, v in sorted(out.items()):
        me = sorted(x[0] for x in v)
        le = sorted(x[1] for x in v if x[1] is not None)
        line = (f"line used at {len(le)}: median {statistics.median(le):.2f} px, "
                f"within 2 px {sum(x < 2 for x in le)}") if le else "line never used"
        print(f"{' '.join(k)}: {len(v)} ends; masks' median error {statistics.median(me):.2f} px, "
              f"within 2 px {sum(x < 2 for x in me)}; {line}")


if __name__ == "__main__":
    main(sys.argv[1:])
