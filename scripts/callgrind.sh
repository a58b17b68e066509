#!/usr/bin/env bash
# Instructions per pixel of the whole core pipeline (segmentation of both
# frames, stereo pairing, length, tracking) on one stereo frame pair of a
# default synthetic haul, counted by valgrind's callgrind: a count, not a
# time, so it repeats on a noisy shared machine.
#
#   scripts/callgrind.sh [HAUL] [FRAME]
#
# HAUL defaults to target/callgrind-haul (synthesised once: 2048 x 2048,
# seed 1, 5 frames); FRAME defaults to the middle pair. Only instructions
# inside Pipeline::process_frame are counted (frames already rectified in
# memory). Pixels = 2 x width x height (both frames of the pair).
set -euo pipefail
cd "$(dirname "$0")/.."

if ! command -v valgrind >/dev/null; then
    echo "valgrind missing: installing it (apt-get)" >&2
    apt-get update -qq && apt-get install -y -qq valgrind >/dev/null
fi

HAUL=${1:-target/callgrind-haul}
cargo build --release -q -p fishtrack --bin fishtrack --example core_pair
if [ ! -d "$HAUL" ]; then
    target/release/fishtrack synth "$HAUL" --seed 1 --frames 5 >/dev/null
fi
FRAME_ARGS=()
if [ -n "${2:-}" ]; then FRAME_ARGS=(--frame "$2"); fi

out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
valgrind --tool=callgrind --callgrind-out-file="$out/cg.out" \
    --toggle-collect='*Pipeline*process_frame*' \
    target/release/examples/core_pair "$HAUL" "${FRAME_ARGS[@]}" >"$out/run.txt" 2>"$out/vg.txt"
instr=$(grep -m1 'Collected :' "$out/vg.txt" | awk '{print $4}' | tr -d ,)
pixels=$(grep -o '[0-9]* pixels per pair' "$out/run.txt" | awk '{print $1}')
frame=$(awk '{print $2}' "$out/run.txt")
echo "haul $HAUL, frame $frame: $instr instructions in Pipeline::process_frame for $pixels pixels"
awk -v i="$instr" -v p="$pixels" 'BEGIN { printf "instructions/pixel: %.2f\n", i / p }'
if command -v callgrind_annotate >/dev/null; then
    echo "top functions (exclusive):"
    callgrind_annotate "$out/cg.out" 2>/dev/null | grep -E '^ *[0-9,]+ \(' | sed -n '2,9p' |
        sed -E 's#/[^ ]*/(core|library)/#\1/#; s# \[.*##'
fi
