#!/usr/bin/env bash
# scripts/clang_check.sh [SOURCE...]: compile sources with Clang 14 up to code generation
# (-fsyntax-only: parsing, templates instantiated, no object files), so that the headers stay
# usable from Clang as well as GCC. Without arguments: the rasteriser and binning tests, which
# instantiate the projection, binning and blend kernels for every lane type. Two sources at a time;
# any error or warning fails the run.
set -euo pipefail
cd "$(dirname "$0")/.."
cxx=${MSGS_CLANG:-clang++-14}
if ! command -v "$cxx" >/dev/null; then
  echo "clang_check: $cxx not found (scripts/setup.sh installs clang-14; MSGS_CLANG names another)" >&2
  exit 1
fi
if [ $# -eq 0 ]; then
  set -- tests/test_bin.cpp tests/test_rasterize_reference.cpp tests/test_rasterize_gradients.cpp \
    tests/test_rasterize_hard_cases.cpp tests/test_rasterize_determinism.cpp tests/test_rasterize_single.cpp
fi
# shellcheck disable=SC2046  # pkg-config's flags are meant to split
flags=(-std=gnu++20 -fopenmp -march=native -ffp-contract=off -fno-math-errno -Wall -Wextra -Wshadow
  -Wno-unknown-pragmas -Werror -DMSGS_HAVE_FREETYPE=1 -Iinclude -Itests -Iexamples
  $(pkg-config --cflags-only-I eigen3 stb freetype2 | sed 's/-I/-isystem /g'))
printf '%s\n' "$@" | xargs -P 2 -I{} sh -c 'echo "clang_check: {}"; "$0" "$@" -fsyntax-only {}' "$cxx" "${flags[@]}"
echo "clang_check: $# source(s) compile with $cxx"
