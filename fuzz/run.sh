#!/usr/bin/env bash
# fuzz/run.sh [SECONDS] [BUILD_DIR]: build the libFuzzer targets with clang and fuzz each one for
# SECONDS (default 25) from the seed corpus in fuzz/corpus/<name>, as many at a time as there are
# cores. New inputs go to a scratch corpus, never into the repository; a crash, leak, timeout or
# out-of-memory leaves its input in BUILD_DIR/fuzz-artifacts/ and fails the script. Reproduce one
# with: BUILD_DIR/fuzz/<target> <file>.
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${1:-25}
dir=${2:-build-fuzz}
cxx=${MSGS_FUZZ_CXX:-clang++-14}
jobs=$(nproc 2>/dev/null || echo 2)
targets=(fuzz_ply fuzz_dataset fuzz_image fuzz_colmap fuzz_import_meta)
cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER="$cxx" -DMSGS_BUILD_FUZZ=ON \
  -DMSGS_BUILD_TESTS=OFF -DMSGS_BUILD_BENCHMARKS=OFF -DMSGS_BUILD_EXAMPLES=OFF >/dev/null
cmake --build "$dir" -j "$jobs" --target msgs_fuzzers
art="$dir/fuzz-artifacts"
mkdir -p "$art"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
# UBSan findings are fatal (-fno-sanitize-recover in fuzz/CMakeLists.txt); leaks are checked.
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1}
# One target per core at a time; each writes its log and exit status to the scratch folder.
fuzz_one() {
  local t=$1 rc=0
  mkdir -p "$scratch/$t"
  "$dir/fuzz/$t" -max_total_time="$secs" -timeout=10 -rss_limit_mb=2048 -max_len=8192 \
    -print_final_stats=1 -artifact_prefix="$art/$t-" "$scratch/$t" "fuzz/corpus/${t#fuzz_}" \
    >"$scratch/$t.log" 2>&1 || rc=$?
  echo "$rc" >"$scratch/$t.rc"
}
running=0
for t in "${targets[@]}"; do
  echo "fuzz: $t for ${secs}s"
  fuzz_one "$t" &
  if (( ++running >= jobs )); then wait -n; running=$((running - 1)); fi
done
wait
status=0
for t in "${targets[@]}"; do
  if [ "$(cat "$scratch/$t.rc")" != 0 ]; then
    echo "fuzz: $t FOUND A PROBLEM; log tail:"
    tail -n 60 "$scratch/$t.log"
    status=1
  else
    echo -n "fuzz: $t: "
    grep -E "stat::number_of_executed_units|stat::peak_rss_mb" "$scratch/$t.log" | tr '\n' ' '
    echo
  fi
done
exit $status
