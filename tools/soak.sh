#!/usr/bin/env bash
# Soak: trains the tiny scene for DISPFLOW_SOAK_STEPS (default 10 000) iterations with
# densification (first half) and the motion loss, sampling RSS and device memory every 500
# steps into soak.csv (or $1), and fails when device memory grows after densification.
# Not run by CI (hours on lavapipe); CI runs the 200-step version in tests/soak.rs.
set -euo pipefail
cd "$(dirname "$0")/.."
out="$(realpath -m "${1:-soak.csv}")"
DISPFLOW_SOAK_CSV="$out" cargo test --release --test soak soak_long -- --ignored --nocapture
echo "soak curve: $out"
