#!/usr/bin/env bash
# Short fuzzing smoke run (CI): each cargo-fuzz target in fuzz/ for
# FUZZ_SECONDS seconds (default 12; 4 targets ≈ 50 s of fuzzing) starting
# from its committed corpus. The corpus is not modified (new inputs go to a
# temporary directory). A crash fails the script and leaves the input in
# fuzz/artifacts/TARGET/.
#
#   scripts/fuzz-smoke.sh            # all targets
#   FUZZ_SECONDS=600 scripts/fuzz-smoke.sh segment   # a real run of one
#   FUZZ_SANITIZER=address scripts/fuzz-smoke.sh     # with AddressSanitizer
#
# Sanitizer: none by default (session 36). The workspace has no `unsafe`
# code (core denies it; Miri checks core, scripts/miri.sh), so the fuzzing
# looks for panics, hangs and overflows, which need no sanitizer. Without
# AddressSanitizer the build took 5 min 23 s instead of 7 min 53 s on 2
# cores, and the segment target ran 23 538 inputs in 12 s instead of 7 880.
#
# Needs the nightly toolchain and cargo-fuzz (`cargo install cargo-fuzz
# --locked`); if they are missing and cannot be installed, the script says
# so and exits 0.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT/fuzz"
SECONDS_EACH="${FUZZ_SECONDS:-12}"
TARGETS=("$@")
if [ ${#TARGETS[@]} -eq 0 ]; then
    TARGETS=(segment link_decoder calib_yaml params_toml)
fi

if ! command -v rustup >/dev/null 2>&1 || ! rustup toolchain list | grep -q '^nightly'; then
    echo "fuzz-smoke.sh: no nightly toolchain; fuzzing smoke run SKIPPED"
    exit 0
fi
if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz-smoke.sh: installing cargo-fuzz"
    if ! cargo install cargo-fuzz --locked; then
        echo "fuzz-smoke.sh: cannot install cargo-fuzz; fuzzing smoke run SKIPPED"
        exit 0
    fi
fi

SANITIZER="${FUZZ_SANITIZER:-none}"
cargo +nightly fuzz build -O -s "$SANITIZER"
for t in "${TARGETS[@]}"; do
    scratch="$(mktemp -d)"
    log="$scratch.log"
    echo "fuzz-smoke.sh: $t for ${SECONDS_EACH}s"
    # New inputs land in $scratch (the first corpus dir); the committed corpus is only read.
    status=0
    cargo +nightly fuzz run -O -s "$SANITIZER" "$t" "$scratch" "corpus/$t" -- \
        -max_total_time="$SECONDS_EACH" -print_final_stats=1 >"$log" 2>&1 || status=$?
    grep -E '^stat::(number_of_executed_units|new_units_added)' "$log" || true
    if [ "$status" -ne 0 ]; then
        tail -n 40 "$log"
        echo "fuzz-smoke.sh: $t FAILED (exit $status); the input is in fuzz/artifacts/$t/"
        rm -rf "$scratch" "$log"
        exit 1
    fi
    rm -rf "$scratch" "$log"
done
echo "fuzz-smoke.sh: all targets ran without a crash"
