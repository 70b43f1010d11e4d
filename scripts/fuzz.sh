#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/, clang with AddressSanitizer + UndefinedBehaviorSanitizer) and runs each
# for SECONDS (default 30) from its checked-in seed corpus fuzz/corpus/<target>/. New inputs the fuzzer finds go
# to BUILD/corpus/<target>/ (the checked-in corpus is left as it is); a crash, leak, sanitizer report or failed
# property stops with a non-zero exit and leaves the input in BUILD/artifacts/<target>/ (make it a regression
# test: add it to the seed corpus and to tests/io).
#   scripts/fuzz.sh [SECONDS] [BUILD]        e.g. scripts/fuzz.sh 30 build-fuzz
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH=${1:-30}
BUILD=${2:-build-fuzz}
CC=clang CXX=clang++ cmake -S fuzz -B "$BUILD" -G Ninja >/dev/null
cmake --build "$BUILD" -j "$(nproc)"
# One fuzzer per core at a time (each is single-threaded): the same SECONDS each, in less wall time. Each run's
# lines are printed together when it ends, in the targets' order.
run_one() {  # corpus folder; writes $BUILD/fuzz_<target>.report, returns non-zero on a finding
  local corpus=$1 target
  target=$(basename "$corpus")
  mkdir -p "$BUILD/corpus/$target" "$BUILD/artifacts/$target"
  {
    echo "fuzz_$target: ${SECONDS_EACH} s from $(ls "$corpus" | wc -l) seeds"
    if ! "$BUILD/fuzz_$target" -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -max_len=4096 \
        -print_final_stats=1 -artifact_prefix="$BUILD/artifacts/$target/" \
        "$BUILD/corpus/$target" "$corpus" >"$BUILD/fuzz_$target.log" 2>&1; then
      echo "fuzz_$target FAILED: $(ls "$BUILD/artifacts/$target")"
      grep -m5 -E "ERROR|SUMMARY|property failed|runtime error" "$BUILD/fuzz_$target.log" || tail -20 "$BUILD/fuzz_$target.log"
      touch "$BUILD/fuzz_$target.failed"
    else
      grep -E "stat::number_of_executed_units|stat::new_units_added" "$BUILD/fuzz_$target.log" | tr '\n' ' ' || true
      echo
    fi
  } >"$BUILD/fuzz_$target.report"
}
rm -f "$BUILD"/fuzz_*.failed "$BUILD"/fuzz_*.report
parallel=$(nproc)
for corpus in fuzz/corpus/*/; do
  while (($(jobs -rp | wc -l) >= parallel)); do wait -n || true; done
  run_one "$corpus" &
done
wait
status=0
for corpus in fuzz/corpus/*/; do
  target=$(basename "$corpus")
  cat "$BUILD/fuzz_$target.report"
  if [[ -e "$BUILD/fuzz_$target.failed" ]]; then status=1; fi
done
exit $status
