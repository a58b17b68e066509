#!/usr/bin/env python3
"""External oracle for `fishtrack eval`: CLEAR MOT and ID metrics by py-motmetrics.

Usage:
    motmetrics_oracle.py GT.txt PRED.txt [GT2.txt PRED2.txt ...] [--max-distance 0.6]
        Prints, per pair of MOTChallenge files
        (frame,id,bb_left,bb_top,bb_width,bb_height,...), one line holding a
        JSON object with motmetrics' metrics (several pairs per call save
        the interpreter start-up).
    motmetrics_oracle.py --data-dir
        Prints the directory of the data shipped with motmetrics
        (it holds TUD-Campus/gt.txt and TUD-Campus/test.txt).

Conventions (motmetrics 1.4): `mm.io.loadtxt` reads MOTChallenge files with
1-based frames and subtracts 1 from bb_left/bb_top (Matlab convention; IoU is
unaffected); rows with confidence < -1 would be dropped (none here). The IoU
*distance* is 1 - IoU and pairs with distance > max_distance are forbidden, so
`--max-distance 0.6` allows IoU >= 0.4 (motmetrics' own tests use 0.5).
Frames are the union of frames present in either file.
"""

import json
import os
import sys

import numpy as np

# motmetrics 1.4.0 still calls np.asfarray, removed in NumPy 2.0: restore it
# with its documented meaning (convert to a float array) before importing.
if not hasattr(np, "asfarray"):
    np.asfarray = lambda a, dtype=float: np.asarray(a, dtype=dtype)

import motmetrics as mm  # noqa: E402

METRICS = [
    "num_frames",
    "num_objects",
    "num_predictions",
    "num_matches",
    "num_switches",
    "num_false_positives",
    "num_misses",
    "num_detections",
    "num_transfer",
    "num_ascend",
    "num_migrate",
    "num_unique_objects",
    "mostly_tracked",
    "partially_tracked",
    "mostly_lost",
    "num_fragmentations",
    "mota",
    "motp",
    "precision",
    "recall",
    "idtp",
    "idfp",
    "idfn",
    "idp",
    "idr",
    "idf1",
]


def main(argv):
    if argv[1:] == ["--data-dir"]:
        print(os.path.join(os.path.dirname(mm.__file__), "data"))
        return 0
    args = argv[1:]
    max_distance = 0.6
    if "--max-distance" in args:
        k = args.index("--max-distance")
        max_distance = float(args[k + 1])
        del args[k : k + 2]
    if not args or len(args) % 2 != 0:
        print(__doc__, file=sys.stderr)
        return 2
    mh = mm.metrics.create()
    for gt_path, pred_path in zip(args[0::2], args[1::2]):
        gt = mm.io.loadtxt(gt_path, fmt="mot15-2D")
        pred = mm.io.loadtxt(pred_path, fmt="mot15-2D")
        acc = mm.utils.compare_to_groundtruth(gt, pred, "iou", distth=max_distance)
        summary = mh.compute(acc, metrics=METRICS, return_dataframe=False)
        out = {k: (None if v != v else float(v)) for k, v in summary.items()}
        out["motmetrics_version"] = mm.__version__
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
