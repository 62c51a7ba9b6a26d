#!/usr/bin/env bash
# Runs one fuzz target on the stable toolchain. Usage: bash fuzz/run.sh TARGET [SECONDS] [extra libFuzzer flags]
# TARGET: pcd, ply, npy or text. Inputs found grow fuzz/corpus/TARGET (git-ignored, seeds kept);
# a crash, a hang (> 10 s per input) or an input needing > 2 GiB is written to
# fuzz/artifacts/TARGET/ and ends the run with a non-zero status.
#
# cargo-fuzz normally wants nightly for the sanitizer flags. With `-s none` it only passes the
# coverage instrumentation flags; RUSTC_BOOTSTRAP=1 lets the stable compiler accept the one
# unstable flag cargo-fuzz still adds. Safe Rust needs no AddressSanitizer: panics, aborts, hangs
# and oversized allocations are what the fuzzer catches.
set -euo pipefail
cd "$(dirname "$0")/.."
target=${1:?usage: fuzz/run.sh TARGET [SECONDS]}
seconds=${2:-600}
shift $(( $# >= 2 ? 2 : 1 ))
export RUSTC_BOOTSTRAP=1
exec cargo fuzz run --sanitizer none --release "$target" -- \
    -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=16384 \
    -print_final_stats=1 "$@"
