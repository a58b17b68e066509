#!/usr/bin/env python3
"""Per-seed accounting of the count error of `fishtrack track` (README,
tracking round 5): tracks - countable fish = split + duplicate + false +
non-countable - missed.

    python3 scripts/track_accounting.py HAUL OUT [-v]

A fish frame is countable when its visible left area >= theta_A^L (2000 px
at 2048, scaled by the frame area, as `fishtrack eval`); boxes of tracks.csv
are matched to the truth's left boxes one-to-one (Hungarian, scipy) at
IoU >= 0.4. A counted track (fish.csv) is a *duplicate* when every
observed box of it (all but one from three boxes on) is also, at IoU > 0.9,
a box of another track with at least as many rows; *false* when it matches
no fish; otherwise its fish is the one it matches most often. A countable
fish with k > 1 such tracks adds k - 1 *split* tracks; one with none is
*missed*; a track whose fish is never countable is *non-countable*.
-v prints every split fish's tracks and truth path.
"""
import collections
import csv
import json
import sys

import numpy as np
from scipy.optimize import linear_sum_assignment
def iou(a, b):
    ax1, ay1, ax2, ay2 = a[0], a[1], a[0]+a[2], a[1]+a[3]
    bx1, by1, bx2, by2 = b[0], b[1], b[0]+b[2], b[1]+b[3]
    iw = max(0, min(ax2, bx2)-max(ax1, bx1)); ih = max(0, min(ay2, by2)-max(ay1, by1))
    u = a[2]*a[3]+b[2]*b[3]-iw*ih
    return iw*ih/u if u > 0 else 0
haul, out = sys.argv[1], sys.argv[2]
t = json.load(open(haul+'/truth.json'))
amin = 2000*(t["width"]/2048)**2
truth = collections.defaultdict(list)  # frame -> [(fish, box, countable)]
countable = set()
for f in t['fish']:
    for fr in f['frames']:
        if fr['left_box'] is None: continue
        c = fr['left_area'] >= amin
        truth[fr['frame']].append((f['id'], fr['left_box'], c))
        if c: countable.add(f['id'])
rows = collections.defaultdict(list)
tracks = collections.defaultdict(list)
for r in csv.reader(open(out+'/tracks.csv')):
    fr, tid = int(r[0]), int(r[1]); box = [float(x) for x in r[2:6]]; conf = float(r[6])
    rows[fr].append((tid, box, conf)); tracks[tid].append((fr, box, conf))
ids = set(int(r[0]) for r in list(csv.reader(open(out+'/fish.csv')))[1:])
match = collections.defaultdict(collections.Counter)  # track -> fish counter
for fr, rs in rows.items():
    tr = truth.get(fr, [])
    if not tr or not rs: continue
    M = np.array([[iou(b, tb) for (_, tb, _) in tr] for (_, b, _) in rs])
    ri, ci = linear_sum_assignment(-M)
    for i, j in zip(ri, ci):
        if M[i, j] >= 0.4: match[rs[i][0]][tr[j][0]] += 1
dup, false_, dom = [], [], {}
for tid in sorted(ids):
    obs = [(fr, b) for (fr, b, c) in tracks[tid] if c >= 1]
    # duplicate: (nearly) every observed box is also another, longer track's box
    best = 0
    for o in ids:
        if o == tid or len(tracks[o]) < len(tracks[tid]): continue
        ob = {(fr): b for (fr, b, c) in tracks[o] if c >= 1}
        s = sum(1 for fr, b in obs if fr in ob and iou(b, ob[fr]) > 0.9)
        best = max(best, s)
    if obs and best >= len(obs) - (1 if len(obs) >= 3 else 0):
        dup.append(tid); continue
    if not match[tid]:
        false_.append(tid); continue
    dom[tid] = match[tid].most_common(1)[0][0]
per = collections.Counter(dom.values())
split = sum(n-1 for f, n in per.items())
noncount = [tid for tid, f in dom.items() if f not in countable]
missed = [f for f in countable if per[f] == 0]
n = len(ids); nf = len(countable)
print(f"tracks {n} countable {nf} err {100*(n-nf)/nf:+.1f}% | split +{split} dup +{len(dup)} false +{len(false_)} noncountable +{len(noncount)} missed -{len(missed)}  dup={dup} false={false_}")
if '-v' in sys.argv:
    hits = collections.Counter()
    for tid in ids:
        hits[tid] = sum(1 for (fr, b, c) in tracks[tid] if c >= 1)
    one = [tid for tid in ids if hits[tid] == 1]
    cls = collections.Counter()
    for tid in one:
        if tid in dup: cls['dup'] += 1
        elif tid in false_: cls['false'] += 1
        elif per[dom[tid]] > 1: cls['split'] += 1
        else: cls['sole'] += 1
    print("  one-hit tracks:", dict(cls))
if '-v' in sys.argv:
    for f, n in per.items():
        if n < 2: continue
        print(f"  fish {f}:")
        for tid in sorted(k for k, v in dom.items() if v == f):
            s = ' '.join(f"f{fr}{'' if c>=1 else '?'}({b[0]+b[2]/2:.0f},{b[1]+b[3]/2:.0f})" for fr, b, c in sorted(tracks[tid]))
            print(f"    t{tid} {dict(match[tid])}: {s}")
        tf = [(fr['frame'], fr['left_box'], fr['left_area']) for ff in t['fish'] if ff['id'] == f for fr in ff['frames'] if fr['left_box']]
        print("    truth:", ' '.join(f"f{a}({b[0]+b[2]/2:.0f},{b[1]+b[3]/2:.0f};{c:.0f})" for a, b, c in tf))
