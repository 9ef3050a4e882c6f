#!/usr/bin/env bash
# scripts/demo.sh: the main job on the built-in default. Installs dependencies, builds the `msgs`
# tool, generates the `small` synthetic multi-spectral scene and trains Joint-Optimized
# (Joint + SpecDelay + MSAD) on it at schedule scale 0.025 (3000 steps), then prints the per-band table.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build --target msgs_cli -j "$jobs"
data=${MSGS_DEMO_DATA:-out/small}
[ -f "$data/transforms.json" ] || ./build/examples/msgs synth --preset small --out "$data" --force
./build/examples/msgs train --data "$data" --strategy joint-optimized --scale "${MSGS_DEMO_SCALE:-0.025}" \
  --out out/demo_joint_optimized
