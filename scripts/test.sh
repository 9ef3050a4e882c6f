#!/usr/bin/env bash
# scripts/test.sh: install dependencies, build everything, run the test suite, and prove that a
# downstream project can find_package(msgs) from an install.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh build
jobs=$(nproc 2>/dev/null || echo 2)
(cd build && ctest --output-on-failure -j "$jobs")
# Downstream consumer against the installed package.
prefix=$(mktemp -d)
trap 'rm -rf "$prefix"' EXIT
cmake --install build --prefix "$prefix/install" >/dev/null
cmake -S tests/downstream -B "$prefix/build" -DCMAKE_PREFIX_PATH="$prefix/install" >/dev/null
cmake --build "$prefix/build" -j "$jobs" >/dev/null
"$prefix/build/downstream"
