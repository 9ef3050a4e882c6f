#!/usr/bin/env bash
# scripts/setup.sh: install the Debian packages msgs needs (idempotent; skips apt when all are present).
set -euo pipefail
pkgs=(build-essential cmake pkg-config libeigen3-dev libglm-dev libomp-dev doctest-dev libbenchmark-dev
      libstb-dev nlohmann-json3-dev libtiff-dev libpng-dev zlib1g-dev libnanoflann-dev gnuplot-nox
      clang-14 libclang-rt-14-dev  # clang + its libFuzzer/ASan runtimes for fuzz/run.sh
      colmap exiv2  # `msgs import`: poses (CPU COLMAP, run headless) and camera metadata
      libcpp-httplib-dev  # `msgs view`: the HTTP server of the browser viewer (links the tool only)
      libfreetype-dev fonts-dejavu-core  # words in pictures (contact-sheet labels, legend values)
      chromium)  # headless browser of tests/test_view_browser.cpp (about 113 MB to download)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
