#!/usr/bin/env bash
# Scale benchmark (issue 18): 0.1M-6M splats built from the shared real files, then the LOD
# benchmark on 3M and 6M.  One run per group of sizes keeps each timed run short; the merge
# gives one table, scale.json and the log-log plot.  On a shared machine prefix each line with
# /work/tools/timed.  OUT defaults to bench-scale/.
set -euo pipefail
OUT=${OUT:-bench-scale}
splatgl bench --scale --sizes 0.1M,0.3M --sh3-sizes none --out "$OUT/a" --force
splatgl bench --scale --sizes 1M --sh3-sizes 1M --out "$OUT/b" --force
splatgl bench --scale --sizes 3M,6M --sh3-sizes none --out "$OUT/c" --force
splatgl bench --scale --sizes none --sh3-sizes 6M --width 1280 --height 720 --out "$OUT/d" --force
python -m splatgl.commands._bench_tools scale-report "$OUT"/{a,b,c,d}/scale.json --out "$OUT"
splatgl bench --lod --sizes 3M,6M --out "$OUT" --force
splatgl bench --lod --sizes 3M --lod-paths fine --frames 8 --lod-thresholds 1 --lod-budgets none --out "$OUT/fine" --force
