#!/usr/bin/env bash
# Reproduces the benchmark tables in docs/ (about 10 minutes on 2 cores with llvmpipe):
#   docs/bench-1280x720.{txt,csv}, docs/bench.png  -- splatgl bench at 1280x720
#   docs/compare-512x384.md                        -- quad and tile against the reference
# Run from the repository root with splatgl installed; ../shared/scenes must be present.
set -euo pipefail
cd "$(dirname "$0")/.."
out=$(mktemp -d)
splatgl bench --out "$out" | tee docs/bench-1280x720.txt
cp "$out/bench.csv" docs/bench-1280x720.csv
cp "$out/bench.png" docs/bench.png
python benchmarks/compare_table.py > docs/compare-512x384.md
python benchmarks/frame_times.py
