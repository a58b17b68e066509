#!/usr/bin/env python3
"""Why countable fish were missed: a development aid for issue 4's recall.

    scripts/miss_breakdown.py HAUL OUT [--regions SEG_DIAG_CSV] [--list]

Reads HAUL/truth.json and OUT/detections.csv (as `fishtrack eval` does:
countable = visible left area >= 2000 px, hit = a detection of IoU >= 0.4;
not matched one to one as `eval` matches, so its recall can be a little
higher than eval's)
and sorts every missed countable fish-frame into one class:

- occluded: another fish covers > 20 % of its box;
- border:   the frame border cuts it (not wholly inside the left view);
- partial:  a detection overlaps it, best IoU 0.1-0.4 (split or too small);
- none:     wholly visible, alone, and nothing detected on it.

With --regions (the CSV of `cargo run --release -p fishtrack --example
seg_diag -- --regions HAUL`), each class is split by whether the fish's box
centre lies in a coarse local region (the coarse pass found it, the local
segmentation lost it) or not. --list prints every miss.
"""
import argparse
import csv
import json
import math
import sys


def iou(a, b):
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    ix = max(0.0, min(ax + aw, bx + bw) - max(ax, bx))
    iy = max(0.0, min(ay + ah, by + bh) - max(ay, by))
    i = ix * iy
    u = aw * ah + bw * bh - i
    return i / u if u > 0 else 0.0


def covered_fraction(a, b):
    """Fraction of box a covered by box b."""
    ax, ay, aw, ah = a
    bx, by, bw, bh = b
    ix = max(0.0, min(ax + aw, bx + bw) - max(ax, bx))
    iy = max(0.0, min(ay + ah, by + bh) - max(ay, by))
    return ix * iy / (aw * ah) if aw * ah > 0 else 0.0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("haul")
    ap.add_argument("out")
    ap.add_argument("--regions", help="seg_diag --regions CSV of the haul")
    ap.add_argument("--list", action="store_true", help="print every miss")
    ap.add_argument("--area-min", type=float, default=2000.0)
    a = ap.parse_args()

    truth = json.load(open(f"{a.haul}/truth.json"))
    dets = {}
    for r in csv.reader(open(f"{a.out}/detections.csv")):
        if not r or r[0].startswith("#"):
            continue
        dets.setdefault(int(r[0]), []).append(tuple(map(float, r[2:6])))
    regions = {}
    if a.regions:
        for r in csv.reader(open(a.regions)):
            if r and r[0] == "R":
                regions.setdefault(int(r[2]), []).append(tuple(map(float, r[3:8])))

    def in_region(frame, box):
        cx, cy = box[0] + box[2] / 2, box[1] + box[3] / 2
        for rx, ry, ra, rb, ang in regions.get(frame, []):
            c, s = math.cos(ang), math.sin(ang)
            u = (cx - rx) * c + (cy - ry) * s
            v = -(cx - rx) * s + (cy - ry) * c
            if (u / ra) ** 2 + (v / rb) ** 2 <= 1:
                return True
        return False

    by_frame = {}
    for f in truth["fish"]:
        for fr in f["frames"]:
            if fr.get("left_box"):
                by_frame.setdefault(fr["frame"], []).append((f, fr))
    counts = {}
    total = 0
    for frame, fish in sorted(by_frame.items()):
        for f, fr in fish:
            if fr["left_area"] < a.area_min:
                continue
            total += 1
            box = fr["left_box"]
            best = max([iou(box, d) for d in dets.get(frame, [])] + [0.0])
            if best >= 0.4:
                counts[("hit", None)] = counts.get(("hit", None), 0) + 1
                continue
            cover = max(
                [covered_fraction(box, o["left_box"]) for g, o in fish if g["id"] != f["id"]]
                + [0.0]
            )
            if cover > 0.2:
                cls = "occluded"
            elif not fr["inside_left"]:
                cls = "border"
            elif best > 0.1:
                cls = "partial"
            else:
                cls = "none"
            key = (cls, in_region(frame, box) if a.regions else None)
            counts[key] = counts.get(key, 0) + 1
            if a.list:
                print(
                    f"frame {frame} fish {f['id']} {cls}: area {fr['left_area']:.0f}, "
                    f"visible {fr['left_visible_fraction']:.2f}, box "
                    f"{[round(v) for v in box]}, best IoU {best:.2f}, covered {cover:.2f}"
                    + (f", in a region: {key[1]}" if a.regions else "")
                )
    hits = counts.pop(("hit", None), 0)
    print(f"{a.haul}: {total} countable fish-frames, {hits} hit (recall {hits / max(total, 1):.3f})")
    for (cls, reg), n in sorted(counts.items(), key=lambda kv: (kv[0][0], str(kv[0][1]))):
        where = "" if reg is None else (" (in a coarse region)" if reg else " (no coarse region)")
        print(f"  missed, {cls}{where}: {n}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
