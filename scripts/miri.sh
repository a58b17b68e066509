#!/usr/bin/env bash
# Runs fishtrack-core's unit tests under Miri (undefined-behaviour checker).
#
#   scripts/miri.sh [extra libtest args, e.g. a test-name filter]
#
# The core itself is `#![deny(unsafe_code)]`; Miri checks the unsafe code of
# its dependencies (heapless, bytemuck, nalgebra, postcard, crc, micromath)
# as the core's tests drive it. Under Miri, proptests run a handful of cases
# (`if cfg!(miri)` in their ProptestConfig) and tests that are too slow to
# interpret (full 2048² frames, long sequences) are `#[cfg_attr(miri, ignore)]`
# with a comment saying why.
#
# Needs the nightly toolchain with the `miri` and `rust-src` components; if
# they are missing and cannot be installed, the script says so and exits 0.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

if ! command -v rustup >/dev/null 2>&1 || ! rustup toolchain list | grep -q '^nightly'; then
    echo "miri.sh: no nightly toolchain (rustup toolchain install nightly); Miri run SKIPPED"
    exit 0
fi
if ! cargo +nightly miri --version >/dev/null 2>&1; then
    echo "miri.sh: installing the miri and rust-src components"
    if ! rustup component add --toolchain nightly miri rust-src; then
        echo "miri.sh: cannot install Miri; Miri run SKIPPED"
        exit 0
    fi
fi
# Separate target dir: Miri's artefacts never evict the normal build's.
export CARGO_TARGET_DIR="$ROOT/target/miri"
cargo +nightly miri setup
# Isolation off: proptest reads its *.proptest-regressions files.
export MIRIFLAGS="${MIRIFLAGS:--Zmiri-disable-isolation}"
# libm's x86 `sqrtf` is inline assembly, which Miri cannot run; its
# `force-soft-floats` feature selects the portable (equally IEEE-exact) code.
cargo +nightly miri test -p fishtrack-core --features libm/force-soft-floats -- "$@"
