#!/usr/bin/env bash
# Installs what FishTrack's tests need beyond the Rust toolchain: OpenCV,
# numpy and motmetrics (the external oracles), socat (pseudo-terminal pairs),
# the thumbv7em target (no_std cross-build) and nightly's rust-src (build-std,
# Miri). Idempotent; safe to rerun.
set -euo pipefail
cd "$(dirname "$0")/.."

if ! python3 -c 'import cv2, numpy, motmetrics' 2>/dev/null; then
  python3 -m pip install --quiet --disable-pip-version-check -r scripts/requirements.txt
fi
if ! command -v socat >/dev/null 2>&1; then
  if command -v apt-get >/dev/null 2>&1; then
    (apt-get update -qq && apt-get install -y -qq socat) >/dev/null
  else
    echo "setup: socat not installed and no apt-get; pty tests use serialport's own pairs" >&2
  fi
fi
rustup target add thumbv7em-none-eabihf >/dev/null 2>&1 \
  || echo "setup: could not add thumbv7em-none-eabihf; the no_std check falls back to a host build" >&2
rustup component add --toolchain nightly rust-src miri >/dev/null 2>&1 \
  || echo "setup: could not add nightly rust-src/miri; build-std and Miri checks are skipped" >&2
