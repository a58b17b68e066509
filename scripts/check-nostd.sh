#!/usr/bin/env bash
# Proves that fishtrack-core builds with no `std` and no `alloc` anywhere in
# its dependency tree, with and without the `defmt` feature, and reports the
# size of the code compiled into the core's rlib.
#
#   scripts/check-nostd.sh            # from anywhere inside the workspace
#
# Steps
#  1. stable:  cargo build --release -p fishtrack-core --target thumbv7em-none-eabihf [--features defmt]
#     thumbv7em-none-eabihf ships a `core`/`alloc` but no `std`: any crate
#     using std fails here.
#  2. nightly: cargo +nightly check -Z build-std=core -p fishtrack-core --target thumbv7em-none-eabihf [--features defmt]
#     Only `core` (and compiler_builtins) is built from source (`check`: type
#     checking is enough, and much faster than code generation), so a crate
#     anywhere in the tree doing `extern crate alloc` (or std) fails to compile.
#  3. size: text/data/bss of the object files inside the release rlib
#     (llvm-size / arm-none-eabi-size / size).
#
# Needs: rustup target thumbv7em-none-eabihf (stable) and the nightly
# toolchain with rust-src. CI installs them first:
#   rustup target add thumbv7em-none-eabihf
#   rustup component add --toolchain nightly rust-src
# If they are missing and cannot be added, the script says so and falls back
# to a host build (which proves much less: the host has std).
set -euo pipefail

TARGET=thumbv7em-none-eabihf
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
# Separate target dir for nightly build-std artefacts, so they do not evict
# the stable ones.
NOSTD_DIR="$ROOT/target/nostd"
FEATURE_SETS=("" "defmt")
status=0

say() { printf '\n== %s\n' "$*"; }
feature_args() { if [ -n "$1" ]; then echo "--features $1"; fi; }
feature_name() { if [ -n "$1" ]; then echo "features: $1"; else echo "default features"; fi; }

have_rustup=0
command -v rustup >/dev/null 2>&1 && have_rustup=1

# --- toolchain checks -------------------------------------------------------
have_target=0
if [ "$have_rustup" = 1 ]; then
    if rustup target list --installed 2>/dev/null | grep -qx "$TARGET"; then
        have_target=1
    else
        say "target $TARGET not installed; trying: rustup target add $TARGET"
        if rustup target add "$TARGET"; then have_target=1; fi
    fi
else
    # No rustup: trust rustc's sysroot.
    if [ -d "$(rustc --print sysroot)/lib/rustlib/$TARGET" ]; then have_target=1; fi
fi

have_nightly_src=0
if [ "$have_rustup" = 1 ] && rustup run nightly rustc --version >/dev/null 2>&1; then
    if rustup component list --toolchain nightly --installed 2>/dev/null | grep -q '^rust-src'; then
        have_nightly_src=1
    else
        say "nightly rust-src not installed; trying: rustup component add --toolchain nightly rust-src"
        if rustup component add --toolchain nightly rust-src; then have_nightly_src=1; fi
    fi
fi

# --- 1. stable cross builds -------------------------------------------------
if [ "$have_target" = 1 ]; then
    for f in "${FEATURE_SETS[@]}"; do
        say "stable: cargo build --release -p fishtrack-core --target $TARGET $(feature_args "$f")"
        # shellcheck disable=SC2046
        if cargo build --release -p fishtrack-core --target "$TARGET" $(feature_args "$f"); then
            echo "OK   stable $TARGET ($(feature_name "$f"))"
        else
            echo "FAIL stable $TARGET ($(feature_name "$f"))"
            status=1
        fi
    done
else
    say "FALLBACK: target $TARGET is not available and could not be added."
    say "Host build only — this does NOT prove the absence of std/alloc."
    for f in "${FEATURE_SETS[@]}"; do
        # shellcheck disable=SC2046
        if cargo build -p fishtrack-core $(feature_args "$f"); then
            echo "OK   host build ($(feature_name "$f"))"
        else
            echo "FAIL host build ($(feature_name "$f"))"
            status=1
        fi
    done
fi

# --- 2. nightly build-std=core: no alloc anywhere in the tree ---------------
if [ "$have_nightly_src" = 1 ]; then
    for f in "${FEATURE_SETS[@]}"; do
        say "nightly: cargo +nightly check -Z build-std=core -p fishtrack-core --target $TARGET $(feature_args "$f")"
        # shellcheck disable=SC2046
        if cargo +nightly check -Z build-std=core -p fishtrack-core --target "$TARGET" \
            --target-dir "$NOSTD_DIR" $(feature_args "$f"); then
            echo "OK   core-only sysroot ($(feature_name "$f")): no crate in the tree uses alloc or std"
        else
            echo "FAIL core-only sysroot ($(feature_name "$f")): some crate needs alloc or std (see above)"
            status=1
        fi
    done
else
    say "SKIPPED: nightly toolchain with rust-src is not available and could not be added;"
    echo "the no-alloc proof (-Z build-std=core) was not run."
    [ "${FISHTRACK_REQUIRE_NOSTD:-0}" = 1 ] && status=1
fi

# --- 3. code size -----------------------------------------------------------
if [ "$have_target" = 1 ]; then
    SIZE=""
    for s in llvm-size arm-none-eabi-size size; do
        if command -v "$s" >/dev/null 2>&1; then SIZE="$s"; break; fi
    done
    RLIB="$ROOT/target/$TARGET/release/libfishtrack_core.rlib"
    say "size of the release rlib for $TARGET (measured with: ${SIZE:-nothing})"
    for f in "${FEATURE_SETS[@]}"; do
        # Rebuild (cached) so the rlib matches the feature set being measured.
        # shellcheck disable=SC2046
        cargo build --release -q -p fishtrack-core --target "$TARGET" $(feature_args "$f") || continue
        echo "-- $(feature_name "$f")"
        echo "rlib file: $(wc -c <"$RLIB") bytes (object code + crate metadata)"
        if [ -n "$SIZE" ]; then
            tmp="$(mktemp -d)"
            (cd "$tmp" && ar x "$RLIB")
            objs=("$tmp"/*.o)
            if [ -e "${objs[0]}" ]; then
                # Berkeley totals: text (code + rodata), data, bss.
                "$SIZE" -t "${objs[@]}" | tail -n 1 |
                    awk '{printf "object code in rlib: text %s  data %s  bss %s  (total %s bytes)\n", $1, $2, $3, $4}'
            fi
            rm -rf "$tmp"
        else
            echo "(no llvm-size/arm-none-eabi-size/size found: object sizes not reported)"
        fi
    done
    echo "Note: generic code (const-generic containers, nalgebra) is instantiated in the"
    echo "      crate that uses it, so it is not in these figures; it lands in the firmware."
fi

if [ "$status" = 0 ]; then
    say "check-nostd: all checks passed"
else
    say "check-nostd: FAILED"
fi
exit "$status"
