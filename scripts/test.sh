#!/usr/bin/env bash
# The README's test command: sets up the oracles, then runs every test of the
# workspace (unit, property, OpenCV/motmetrics oracle, pseudo-terminal and
# end-to-end tests). Tests that need Python fail, rather than skip, when
# FISHTRACK_REQUIRE_PYTHON=1 (set here).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
export FISHTRACK_REQUIRE_PYTHON=1
cargo test --workspace --locked "$@"
