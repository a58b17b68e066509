#!/usr/bin/env python3
"""Thins a haul to a lower frame rate (issue 6's 2.5 fps check; README,
Table V at 2.5 fps): keeps frames 1, 1+k, 1+2k, ... renumbered from 1,
halves (divides by k) truth.json's fps, and keeps each fish's truth rows
on the kept frames (fish seen on none are dropped). Images are hard-linked
(copied across file systems). The truth is thinned as `truth_obs::thin_truth`
(host) thins it for the in-process tracking tests, which read no images.

    python3 scripts/thin_haul.py HAUL OUT [--every K]   # K defaults to 2
"""
import json
import os
import shutil
import sys


def link(src, dst):
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def main(argv):
    every = 2
    if "--every" in argv:
        i = argv.index("--every")
        every = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    if len(argv) != 2 or every < 1:
        sys.exit(__doc__)
    src, dst = argv
    with open(os.path.join(src, "truth.json")) as f:
        truth = json.load(f)
    kept = list(range(1, truth["frames"] + 1, every))
    new = {old: i + 1 for i, old in enumerate(kept)}
    for side in ("left", "right"):
        os.makedirs(os.path.join(dst, side), exist_ok=True)
        for old, n in new.items():
            link(os.path.join(src, side, f"{old:06}.png"),
                 os.path.join(dst, side, f"{n:06}.png"))
    shutil.copy2(os.path.join(src, "calibration.yml"), os.path.join(dst, "calibration.yml"))
    fish = []
    for f in truth["fish"]:
        rows = [dict(r, frame=new[r["frame"]]) for r in f["frames"] if r["frame"] in new]
        if rows:
            fish.append(dict(f, frames=rows))
    truth.update(fps=truth["fps"] / every, frames=len(kept), fish=fish)
    with open(os.path.join(dst, "truth.json"), "w") as f:
        json.dump(truth, f)


if __name__ == "__main__":
    main(sys.argv[1:])
