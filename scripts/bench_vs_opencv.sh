#!/usr/bin/env bash
# FishTrack vs the OpenCV way on the same haul, in the same run.
#
#   scripts/bench_vs_opencv.sh [HAUL] [REPEATS]
#
# Times `fishtrack track HAUL --out TMP` (whole command: calibration,
# rectification maps, every pair read, rectified, segmented, paired,
# measured and tracked, outputs written) and bench/compare_opencv.py on
# the same haul (calibration to last pair: imread, remap, mesh removal,
# gradient, threshold, connected components, per-object processing),
# alternating the two REPEATS times (default 3), and prints each one's
# median wall time per pair and the ratio FishTrack / OpenCV.
# HAUL defaults to target/bench-haul (synthesised once: 2048 x 2048, seed 1,
# 10 frames).
set -euo pipefail
cd "$(dirname "$0")/.."
HAUL=${1:-target/bench-haul}
REPEATS=${2:-3}
cargo build --release -q -p fishtrack --bin fishtrack
if [ ! -d "$HAUL" ]; then
    target/release/fishtrack synth "$HAUL" --seed 1 --frames 10 >/dev/null
fi
pairs=$(find "$HAUL/left" -maxdepth 1 -name '*.png' | wc -l)
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
ft=()
cv=()
for _ in $(seq "$REPEATS"); do
    t0=$(date +%s.%N)
    target/release/fishtrack track "$HAUL" --out "$out/track" >/dev/null
    t1=$(date +%s.%N)
    ft+=("$(echo "$t1 - $t0" | bc -l)")
    cv+=("$(python3 bench/compare_opencv.py "$HAUL" --repeats 1 --json |
        python3 -c 'import json,sys; print(json.load(sys.stdin)["seconds"])')")
done
python3 - "$pairs" "${#ft[@]}" "${ft[@]}" "${cv[@]}" <<'PY'
import statistics, sys
pairs, n = int(sys.argv[1]), int(sys.argv[2])
ft = [float(x) for x in sys.argv[3:3 + n]]
cv = [float(x) for x in sys.argv[3 + n:3 + 2 * n]]
f, c = statistics.median(ft), statistics.median(cv)
print(f"pairs: {pairs}, runs: {n} each, alternating")
print(f"fishtrack track : {1e3 * f / pairs:8.1f} ms/pair  (runs: {', '.join(f'{x:.2f}' for x in ft)} s)")
print(f"OpenCV script   : {1e3 * c / pairs:8.1f} ms/pair  (runs: {', '.join(f'{x:.2f}' for x in cv)} s)")
print(f"ratio fishtrack/OpenCV: {f / c:.3f} (target <= 0.3)")
PY
