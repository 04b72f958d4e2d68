#!/usr/bin/env bash
# Reproduces the benchmark tables in docs/results/ (about 10 minutes on 2 cores with llvmpipe):
#   docs/results/bench-1280x720.{txt,csv}, docs/results/bench.png  -- splatgl bench at 1280x720
#   docs/results/compare-512x384.md                -- quad and tile against the reference
# Run from the repository root with splatgl installed; ../shared/scenes must be present.
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(mktemp -d)
mkdir -p docs/results
splatgl bench --out "$out" --force | tee docs/results/bench-1280x720.txt
cp "$out/bench.csv" docs/results/bench-1280x720.csv
cp "$out/bench.png" docs/results/bench.png
python benchmarks/compare_table.py > docs/results/compare-512x384.md
python benchmarks/frame_times.py
