#!/usr/bin/env python3
"""Pools `fishtrack eval` over many synthetic hauls (README, "Where
FishTrack stands (measured)": figures over seeds, never one seed).

    python3 scripts/pool_eval.py HAULDIR OUTDIR SEED... [-- TRACK ARGS...]

Runs `fishtrack track HAULDIR/hSEED --out OUTDIR/hSEED TRACK ARGS` and
`fishtrack eval --json` for every seed (two at a time), writes every
seed's eval to OUTDIR/eval_SEED.json and prints the pooled figures:
segmentation precision and recall (detections.csv), tracking success
(fish correctly labelled / countable fish), detection
precision and recall after tracking, count error (tracks / fish - 1),
identity switches, IDF1 and MOTA from the pooled MOT counts, and the
per-frame stereo and per-fish length MAPE weighted by the fish measured.
The binary is FISHTRACK (default target/release/fishtrack).
"""
import concurrent.futures
import json
import os
import subprocess
import sys


def run(binary, hauldir, outdir, seed, extra):
    haul = os.path.join(hauldir, f"h{seed}")
    out = os.path.join(outdir, f"h{seed}")
    subprocess.run([binary, "-q", "track", haul, "--out", out, *extra], check=True)
    ev = subprocess.run([binary, "eval", haul, out, "--json"], check=True,
                        capture_output=True, text=True).stdout
    with open(os.path.join(outdir, f"eval_{seed}.json"), "w") as f:
        f.write(ev)
    return json.loads(ev)


def pool(evals):
    s = dict(tp=0, fp=0, fn=0, fish=0, ok=0, tracks=0, count_fish=0, sw=0,
             idtp=0, idfp=0, idfn=0, objects=0, miss=0, mfp=0,
             f_meas=0, f_able=0, f_err=0.0, p_meas=0, p_able=0, p_err=0.0,
             stp=0, sfp=0, sfn=0)
    for e in evals:
        t = e["tracking"]
        d, m = t["detection"], t["mot"]
        s["tp"] += d["tp"]; s["fp"] += d["fp"]; s["fn"] += d["fn_"]
        s["fish"] += t["success"]["fish"]; s["ok"] += t["success"]["correctly_labelled"]
        s["tracks"] += t["count"]["tracks"]; s["count_fish"] += t["count"]["fish"]
        s["sw"] += m["num_switches"]; s["objects"] += m["num_objects"]
        s["miss"] += m["num_misses"]; s["mfp"] += m["num_false_positives"]
        s["idtp"] += m["idtp"]; s["idfp"] += m["idfp"]; s["idfn"] += m["idfn"]
        sd = e["segmentation"]["detection"]
        s["stp"] += sd["tp"]; s["sfp"] += sd["fp"]; s["sfn"] += sd["fn_"]
        fl = e["stereo"]["length"]
        s["f_meas"] += fl["measured"]; s["f_able"] += fl["measurable"]
        s["f_err"] += (fl["mape"] or 0.0) * fl["measured"]
        pl = t["length"]
        s["p_meas"] += pl["measured"]; s["p_able"] += pl["measurable"]
        s["p_err"] += (pl["mape"] or 0.0) * pl["measured"]
    div = lambda a, b: a / b if b else float("nan")
    return {
        "seeds": len(evals),
        "success": div(s["ok"], s["fish"]), "correct": s["ok"], "fish": s["fish"],
        "seg_precision": div(s["stp"], s["stp"] + s["sfp"]),
        "seg_recall": div(s["stp"], s["stp"] + s["sfn"]),
        "det_precision": div(s["tp"], s["tp"] + s["fp"]),
        "det_recall": div(s["tp"], s["tp"] + s["fn"]),
        "count_error": div(s["tracks"], s["count_fish"]) - 1.0,
        "switches": s["sw"],
        "idf1": div(2 * s["idtp"], 2 * s["idtp"] + s["idfp"] + s["idfn"]),
        "mota": 1.0 - div(s["miss"] + s["mfp"] + s["sw"], s["objects"]),
        "frame_mape": div(s["f_err"], s["f_meas"]), "frame_measured": s["f_meas"],
        "frame_measurable": s["f_able"],
        "fish_mape": div(s["p_err"], s["p_meas"]), "fish_measured": s["p_meas"],
        "fish_measurable": s["p_able"],
    }


def main(argv):
    extra = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1:]
    if len(argv) < 3:
        sys.exit(__doc__)
    hauldir, outdir, seeds = argv[0], argv[1], argv[2:]
    binary = os.environ.get("FISHTRACK", "target/release/fishtrack")
    os.makedirs(outdir, exist_ok=True)
    with concurrent.futures.ThreadPoolExecutor(2) as ex:
        evals = list(ex.map(lambda s: run(binary, hauldir, outdir, s, extra), seeds))
    p = pool(evals)
    with open(os.path.join(outdir, "pooled.json"), "w") as f:
        json.dump(p, f, indent=1)
    print(f"seg P/R {p['seg_precision']:.3f}/{p['seg_recall']:.3f}  "
          f"success {p['correct']}/{p['fish']} = {p['success']:.3f}  "
          f"det P/R {p['det_precision']:.3f}/{p['det_recall']:.3f}  "
          f"count {p['count_error']:+.1%}  switches {p['switches']}  "
          f"IDF1 {p['idf1']:.3f}  MOTA {p['mota']:.3f}")
    print(f"per-frame MAPE {p['frame_mape']:.2%} ({p['frame_measured']}/{p['frame_measurable']})  "
          f"per-fish MAPE {p['fish_mape']:.2%} ({p['fish_measured']}/{p['fish_measurable']})")


if __name__ == "__main__":
    main(sys.argv[1:])
