#!/usr/bin/env bash
# The wheels `benchmarks/gpu_check.sh --quick --wheelhouse DIR` installs on a GPU machine that
# reaches no package index (issue 40 item 6): the project's own wheel and what its figures need
# beyond what that machine's image holds, downloaded here for its Python and platform.
#
# usage: benchmarks/gpu_wheels.sh [--dir DIR] [--python-version 3.12] [--limit-mib N] [--numerics]
#   --dir DIR            where the wheels go (default wheelhouse/, ignored by git); emptied first
#   --python-version V   the GPU machine's Python (default 3.12: the device image's)
#   --limit-mib N        the most the wheels may take (default 40: the device carries 64 MiB with
#                        the working tree and the shared scenes, about 18 MiB together)
#   --numerics           also numpy, numba and llvmlite (the device image already has them; for a
#                        machine without them), where they fit
# Needed (the run fails without them): moderngl, glcontext, the project wheel.  Optional, in this
# order, each kept only while the total fits the limit: zstandard (SPZ files), glfw (the window),
# OpenImageIO (image files: the figures write none), then with --numerics numpy, llvmlite, numba.
# What is left out is printed: with it the figures that need it are lost (none, today).
# It also copies the three shared real scenes the figures are built from ($SPLATGL_SHARED_SCENES,
# else ../shared/scenes) into .gpu-scenes/ (ignored), and prints what a device run carries in
# all (the working tree, wheelhouse/, .gpu-scenes/ and .gl/) against the 64 MiB limit.
set -euo pipefail
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PYTHON=${PYTHON:-python3}
dir="$REPO/wheelhouse" pyver=3.12 limit=40 numerics=0
while [ $# -gt 0 ]; do
  case "$1" in
    --dir) dir=$2; shift 2 ;;
    --python-version) pyver=$2; shift 2 ;;
    --limit-mib) limit=$2; shift 2 ;;
    --numerics) numerics=1; shift ;;
    -h|--help) sed -n '2,/^set -euo/{/^set -euo/d;s/^# \{0,1\}//;p}' "${BASH_SOURCE[0]}"; exit 0 ;;
    *) echo "gpu_wheels: error: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
rm -rf "$dir"
mkdir -p "$dir"
platform=(--only-binary=:all: --python-version "$pyver" --implementation cp
          --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64
          --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64
          --platform manylinux1_x86_64)
get() { "$PYTHON" -m pip download -q --no-deps "${platform[@]}" -d "$dir" "$@"; }
mib() { du -sm "$dir" | cut -f1; }

"$PYTHON" -m pip wheel -q --no-deps -w "$dir" "$REPO"
get moderngl glcontext
optional=(zstandard glfw OpenImageIO)
[ "$numerics" -eq 1 ] && optional+=(numpy llvmlite numba)
left=()
for name in "${optional[@]}"; do
  tmp=$(mktemp -d)
  if "$PYTHON" -m pip download -q --no-deps "${platform[@]}" -d "$tmp" "$name" 2>/dev/null; then
    size=$(du -sm "$tmp" | cut -f1)
    if [ $(( $(mib) + size )) -le "$limit" ]; then mv "$tmp"/*.whl "$dir"/
    else left+=("$name (${size} MiB)"); fi
  else
    left+=("$name (no wheel for Python $pyver)")
  fi
  rm -rf "$tmp"
done
ls -1 "$dir"
echo "gpu_wheels: $(mib) MiB in $dir (limit $limit MiB)"
if [ ${#left[@]} -gt 0 ]; then
  echo "gpu_wheels: left out: ${left[*]}"
fi
shared=${SPLATGL_SHARED_SCENES:-$REPO/../shared/scenes}
if [ -d "$shared" ]; then
  rm -rf "$REPO/.gpu-scenes"
  for f in ply/donut_sh0.ply compressed_ply/biker.compressed.ply compressed_ply/guitar.compressed.ply; do
    mkdir -p "$REPO/.gpu-scenes/$(dirname "$f")"
    cp "$shared/$f" "$REPO/.gpu-scenes/$f"
  done
  echo "gpu_wheels: the shared real scenes copied into .gpu-scenes/ ($(du -sm "$REPO/.gpu-scenes" | cut -f1) MiB)"
else
  echo "gpu_wheels: warning: no shared scenes at $shared (set SPLATGL_SHARED_SCENES): none copied" >&2
fi
tree=$(cd "$REPO" && git ls-files -z --cached --others --exclude-standard | xargs -0 -r du -cb 2>/dev/null \
       | awk '$2 == "total" {s += $1} END {print int(s / 1048576)}')
carried=$(du -smc "$dir" "$REPO/.gpu-scenes" "$REPO/.gl" 2>/dev/null | awk '$2 == "total" {print $1}')
echo "gpu_wheels: a device run carries about $((tree + carried)) MiB (working tree $tree, carried $carried; limit 64)"
