#!/usr/bin/env bash
# Ready for a GPU (issue 25): on a machine with an NVIDIA GPU, check that splatgl renders on it
# (EGL picks the GPU, not llvmpipe: the GL renderer string is printed and checked), then run the
# test suite, `splatgl bench` on the shared scenes, the early-termination group and the scale
# benchmark up to 6M splats, and write every result with the machine line into one folder.
#
# usage: benchmarks/gpu_check.sh [options] OUT_DIR   (OUT_DIR optional with --quick)
#   --venv DIR     the virtual environment to use (default: .venv in the repository); made with
#                  $PYTHON -m venv where missing; the project is installed into it with
#                  pip install '.[test,fast,bench]' (PyPI must be reachable)
#   --no-install   use $PYTHON as it is (splatgl with its test, fast and bench extras installed)
#   --steps LIST   the steps after the renderer check (which always runs), comma-separated, of
#                  tests,bench,early-stop,scale (default all); with --steps OUT_DIR may hold an
#                  earlier run, whose files of those steps are replaced
#   --quick        issue 40's figures in under 8 minutes, each saved as it is made (no tests):
#                  the radix sort alone (100k and --sizes keys), both renderers with --sort exact
#                  and --sort gpu at --sizes splats (default 1M,6M; scenes built from the shared
#                  files) and --resolutions (default 1280x720,1920x1080) with their stage times
#                  and transfers (figures.jsonl, a line a figure), then the viewer's flight
#                  (headless) on --flights (default donut,biker,guitar,large: the largest size);
#                  a time guard (--seconds, default 450) skips what would not finish.  OUT_DIR
#                  defaults to docs/results/gpu-<device>-<date>/
#   --wheelhouse DIR  with --quick: install from the wheels of benchmarks/gpu_wheels.sh (no
#                  package index) into a folder on PYTHONPATH, over $PYTHON's own packages
#   --sizes L, --resolutions L, --flights L, --seconds N   --quick's sizes (e.g. 0.02M,0.05M
#                  to try it on llvmpipe), resolutions (WxH,...), flights and time guard
#   --smoke        tiny sizes and a few tests, to try the script itself (no benchmark figures)
#   --dry-run      print the commands; run and check nothing
# environment:
#   SPLATGL_SHARED_SCENES  the shared real scenes (default ../shared/scenes beside the repository)
#   SPLATGL_EGL_DEVICE=N   render on EGL device N (default: the first hardware device)
#   SPLATGL_GPU_CHECK_ALLOW_SOFTWARE=1  go on without nvidia-smi and on a software renderer
#   SPLATGL_GPU_CHECK_SCENES  --quick's built scenes (default /tmp/splatgl-gpu-scenes)
#   SPLATGL_GPU_CHECK_SITE    where --wheelhouse installs (default /tmp/splatgl-gpu-site)
#   PYTHON                 the interpreter (default python3)
# OUT_DIR gets: summary.txt (every step ok or FAILED, with seconds); machine.txt and machine.json
# (the machine line, GL renderer, vendor and version, the EGL devices and vendor files, versions,
# commit); nvidia-smi.txt; install.log; pytest.txt, pytest.xml (JUnit) and test-artifacts/ (the
# images of failed image tests); bench.txt and bench/; early-stop.txt and early-stop/; scale.txt
# and scale/ (runs a-d merged into scale/scale.json and scale.png).  Exit status 0 when every step
# passed, 1 when one failed (a software renderer or a failed install stops at once), 2 on bad usage.
# shellcheck disable=SC2317  # install_env and scale_all are called through step "$@"
set -euo pipefail

REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
PYTHON=${PYTHON:-python3}
ALL_STEPS="tests,bench,early-stop,scale"
REAL_FILES=(ply/donut_sh0.ply compressed_ply/biker.compressed.ply compressed_ply/guitar.compressed.ply)

usage() { sed -n '2,/^# shellcheck/{/^# shellcheck/d;s/^# \{0,1\}//;p}' "${BASH_SOURCE[0]}"; }
bad_usage() { echo "gpu_check: error: $*" >&2; exit 2; }
die() { echo "gpu_check: error: $*" >&2; exit 1; }

venv="$REPO/.venv" install=1 steps=$ALL_STEPS steps_given=0 quick=0 dry=0 out="" full=0
wheelhouse="" sizes=1M,6M resolutions=1280x720,1920x1080 flights=donut,biker,guitar,large seconds=450
while [ $# -gt 0 ]; do
  case "$1" in
    --venv) [ $# -ge 2 ] || bad_usage "--venv needs a folder"; venv=$2; shift 2 ;;
    --no-install) install=0; shift ;;
    --steps) [ $# -ge 2 ] || bad_usage "--steps needs a list"; steps=$2; steps_given=1; shift 2 ;;
    --smoke) quick=1; shift ;;
    --quick) full=1; shift ;;
    --wheelhouse) [ $# -ge 2 ] || bad_usage "--wheelhouse needs a folder"; wheelhouse=$(realpath -m "$2"); shift 2 ;;
    --sizes) [ $# -ge 2 ] || bad_usage "--sizes needs a list"; sizes=$2; shift 2 ;;
    --resolutions) [ $# -ge 2 ] || bad_usage "--resolutions needs a list"; resolutions=$2; shift 2 ;;
    --flights) [ $# -ge 2 ] || bad_usage "--flights needs a list"; flights=$2; shift 2 ;;
    --seconds) [[ $# -ge 2 && $2 =~ ^[0-9]+$ ]] || bad_usage "--seconds needs a whole number"; seconds=$2; shift 2 ;;
    --dry-run) dry=1; shift ;;
    -h|--help) usage; exit 0 ;;
    -*) bad_usage "unknown option $1 (see --help)" ;;
    *) [ -z "$out" ] || bad_usage "one output folder, got '$out' and '$1'"; out=$1; shift ;;
  esac
done
if [ -z "$out" ] && [ "$full" -eq 1 ]; then   # docs/results/gpu-<device>-<date>
  device=$( (nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null || true) | head -1 \
    | tr 'A-Z' 'a-z' | sed 's/nvidia//g; s/[^a-z0-9]\{1,\}/-/g; s/^-//; s/-$//')
  out="$REPO/docs/results/gpu-${device:-software}-$(date -u +%Y-%m-%d)"
fi
[ -n "$out" ] || bad_usage "no output folder (usage: benchmarks/gpu_check.sh [options] OUT_DIR)"
[ -z "$wheelhouse" ] || [ "$full" -eq 1 ] || bad_usage "--wheelhouse goes with --quick"
[ "$full" -eq 0 ] || [ "$quick" -eq 0 ] || bad_usage "--quick or --smoke, not both"
[ "$full" -eq 0 ] || steps=quick
for s in ${steps//,/ }; do
  case ",$ALL_STEPS,renderer,quick," in *",$s,"*) ;; *) bad_usage "--steps: unknown step '$s' (steps: $ALL_STEPS)" ;; esac
done
wants() { case ",$steps," in *",$1,"*) return 0 ;; *) return 1 ;; esac; }

out=$(realpath -m "$out")
venv=$(realpath -m "$venv")
scenes=$(realpath -m "${SPLATGL_SHARED_SCENES:-$REPO/../shared/scenes}")
export SPLATGL_SHARED_SCENES=$scenes
cd "$REPO"
export SPLATGL_PROGRESS=${SPLATGL_PROGRESS:-0}   # logs without progress bars
allow_software=${SPLATGL_GPU_CHECK_ALLOW_SOFTWARE:-0}
failed=0

# Print a command (words quoted where the shell needs it); run it unless --dry-run.
run() {
  local a line="+"
  for a in "$@"; do
    if [[ $a =~ ^[A-Za-z0-9_./=,:+@%-]+$ ]]; then line+=" $a"
    elif [[ $a != *"'"* ]]; then line+=" '$a'"
    else line+=" $(printf '%q' "$a")"; fi
  done
  echo "$line"
  [ "$dry" -eq 1 ] || "$@"
}

# step NAME LOG COMMAND...: run COMMAND with its output also in LOG, record ok/FAILED and time.
step() {
  local name=$1 log=$2 rc t0=$SECONDS
  shift 2
  echo "== $name"
  if [ "$dry" -eq 1 ]; then "$@"; return 0; fi
  set +e
  "$@" 2>&1 | tee "$log"
  rc=${PIPESTATUS[0]}
  set -e
  if [ "$rc" -eq 0 ]; then
    echo "$name: ok ($((SECONDS - t0)) s)" >> "$out/summary.txt"
  elif [ "$rc" -eq 3 ] && grep -q '^skipped: the time guard' "$log"; then
    echo "$name: skipped (the time guard, --seconds $seconds)" >> "$out/summary.txt"
  else
    echo "$name: FAILED (exit $rc, $((SECONDS - t0)) s; see $(basename "$log"))" >> "$out/summary.txt"
    failed=1
  fi
  return "$rc"
}

# ---------------------------------------------------------------- checks before any long work
if [ "$dry" -eq 0 ]; then
  if [ -e "$out" ] && [ ! -d "$out" ]; then bad_usage "$out is a file, not a folder"; fi
  if [ "$steps_given" -eq 0 ] && [ -d "$out" ] && [ -n "$(ls -A "$out")" ]; then
    bad_usage "$out already holds results; name a new folder (or re-run some steps with --steps)"
  fi
  if ! command -v nvidia-smi >/dev/null; then
    [ "$allow_software" = 1 ] || die "nvidia-smi not found: this check is for a machine with an NVIDIA GPU and its driver (SPLATGL_GPU_CHECK_ALLOW_SOFTWARE=1 tries it without one)"
    echo "gpu_check: warning: no nvidia-smi (allowed by SPLATGL_GPU_CHECK_ALLOW_SOFTWARE=1)" >&2
  fi
  if wants tests || wants bench || wants early-stop || wants scale || wants quick; then
    for f in "${REAL_FILES[@]}"; do
      [ -f "$scenes/$f" ] || die "$scenes/$f: shared real scene not found (set SPLATGL_SHARED_SCENES to the shared scenes folder)"
    done
  fi
  mkdir -p "$out"
  { echo "gpu_check $(date -u +%Y-%m-%dT%H:%M:%SZ) on $(hostname)"
    echo "repository $REPO, shared scenes $scenes, steps $steps$([ "$quick" -eq 1 ] && echo ' (--smoke)')"
  } >> "$out/summary.txt"
fi
commit=$(git -C "$REPO" rev-parse HEAD 2>/dev/null || echo unknown)
if [ "$commit" != unknown ] && [ -n "$(git -C "$REPO" status --porcelain --untracked-files=no 2>/dev/null)" ]; then
  commit="$commit (with local changes)"
fi

# ---------------------------------------------------------------- the GPU and the environment
if command -v nvidia-smi >/dev/null || [ "$dry" -eq 1 ]; then
  if [ "$dry" -eq 1 ]; then run nvidia-smi; else nvidia-smi > "$out/nvidia-smi.txt" 2>&1 || true; fi
  run nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || true
fi

install_env() {
  if [ ! -x "$venv/bin/python" ]; then
    run "$PYTHON" -m venv "$venv" || { echo "could not make a venv (Debian: apt-get install python3-venv)"; return 1; }
  fi
  run "$venv/bin/python" -m pip install -q --upgrade pip \
    && run "$venv/bin/python" -m pip install '.[test,fast,bench]'
}
install_wheels() {   # no package index: the wheels of benchmarks/gpu_wheels.sh
  run "$PYTHON" -m pip install -q --no-index --find-links "$wheelhouse" --no-deps --no-compile \
    --upgrade --target "$site" "$wheelhouse"/*.whl
}
if [ -n "$wheelhouse" ]; then
  site=${SPLATGL_GPU_CHECK_SITE:-/tmp/splatgl-gpu-site}
  step install "$out/install.log" install_wheels || die "the install failed; see $out/install.log"
  # the checkout first: the figures are of the tree as it is here (the wheel may be older)
  export PYTHONPATH="$REPO:$site${PYTHONPATH:+:$PYTHONPATH}"
  py=$(command -v "$PYTHON") || die "$PYTHON not found"
elif [ "$install" -eq 1 ]; then
  step install "$out/install.log" install_env || die "the install failed; see $out/install.log"
  py="$venv/bin/python"
else
  py=$(command -v "$PYTHON") || die "$PYTHON not found"
fi

# ---------------------------------------------------------------- the renderer (stops on software)
probe=("$py" -m splatgl.commands._bench_tools gpu-probe --out "$out/machine.json" --commit "$commit")
[ "$allow_software" = 1 ] && probe+=(--allow-software)
step renderer "$out/machine.txt" run "${probe[@]}" \
  || die "the GL renderer check failed (see $out/machine.txt); nothing else was run"

# ---------------------------------------------------------------- --quick: issue 40's figures
# guarded CMD...: run CMD under what is left of the time guard (--seconds from the start); a
# step that would start with under 20 s left is skipped (marked so in summary.txt).
guarded() {
  local left=$((seconds - SECONDS))
  if [ "$left" -lt 20 ]; then echo "skipped: the time guard (--seconds $seconds)"; return 3; fi
  run timeout --kill-after=5 "$left" "$@"
}
quick_figures() {
  local cache=${SPLATGL_GPU_CHECK_SCENES:-/tmp/splatgl-gpu-scenes} files=() f name
  step radix "$out/radix.txt" guarded "$py" benchmarks/radix_sort.py --sizes "100k,$sizes" \
    --repeats 5 --no-old --json "$out/radix.json" || true
  step scenes "$out/scenes.txt" guarded "$py" benchmarks/gpu_figures.py scene "$sizes" --cache "$cache" || true
  [ "$dry" -eq 1 ] || mapfile -t files < <(grep '\.ply$' "$out/scenes.txt" || true)
  [ "$dry" -eq 0 ] || files=("$cache/SIZE.ply")
  if [ ${#files[@]} -gt 0 ]; then
    step renderers "$out/renderers.txt" guarded "$py" benchmarks/gpu_figures.py renderers \
      "${files[@]}" --resolutions "$resolutions" --frames 5 --out "$out/figures.jsonl" \
      --deadline "$(( $(date +%s) + seconds - SECONDS ))" || true
  fi
  local res=${resolutions%%,*}
  for name in ${flights//,/ }; do
    case "$name" in
      donut) f="$scenes/ply/donut_sh0.ply" ;;
      biker) f="$scenes/compressed_ply/biker.compressed.ply" ;;
      guitar) f="$scenes/compressed_ply/guitar.compressed.ply" ;;
      large) [ ${#files[@]} -gt 0 ] || continue; f=${files[-1]} ;;
      *) f=$name; name=$(basename "$name" .ply) ;;
    esac
    step "flight-$name" "$out/flight-$name.txt" guarded "$py" -m splatgl bench --interactive "$f" \
      --width "${res%x*}" --height "${res#*x}" --out "$out/flight-$name" --force || true
  done
}
if wants quick; then
  quick_figures
  if [ "$dry" -eq 0 ]; then
    echo "== summary ($out/summary.txt)"
    cat "$out/summary.txt"
  fi
  exit "$failed"
fi

# ---------------------------------------------------------------- tests and benchmarks
if wants tests; then
  tests=()
  [ "$quick" -eq 1 ] && tests=(tests/gl/test_context.py tests/gl/test_egl_devices.py)
  stamp="$out/.tests-started"
  [ "$dry" -eq 1 ] || touch "$stamp"
  step tests "$out/pytest.txt" run "$py" -m pytest -ra --junitxml="$out/pytest.xml" ${tests[@]+"${tests[@]}"} || true
  if [ "$dry" -eq 0 ]; then   # the images of the image tests that failed in this run
    if [ -d test-artifacts ]; then
      find test-artifacts -type f -newer "$stamp" -print0 | xargs -0 -r cp --parents -t "$out"
    fi
    rm -f "$stamp"
  fi
fi

if wants bench; then
  if [ "$quick" -eq 1 ]; then args=(--quick --frames 2); else args=(); fi
  step bench "$out/bench.txt" run "$py" -m splatgl bench ${args[@]+"${args[@]}"} --out "$out/bench" --force || true
fi

if wants early-stop; then
  if [ "$quick" -eq 1 ]; then args=(--quick --frames 2 --real-splats 20000); else args=(); fi
  step early-stop "$out/early-stop.txt" \
    run "$py" -m splatgl bench --groups early-stop ${args[@]+"${args[@]}"} --out "$out/early-stop" --force || true
fi

# The scale benchmark in benchmarks/scale.sh's four runs (each short; a failed size keeps the
# others), merged into one table, JSON and plot.
scale_all() {
  local s="$out/scale" rc=0
  if [ "$quick" -eq 1 ]; then
    run "$py" -m splatgl bench --scale --sizes 0.02M --sh3-sizes none --width 64 --height 48 \
      --frames 2 --out "$s/a" --force || return 1
    run "$py" -m splatgl.commands._bench_tools scale-report "$s/a/scale.json" --out "$s" || return 1
    return 0
  fi
  run "$py" -m splatgl bench --scale --sizes 0.1M,0.3M --sh3-sizes none --out "$s/a" --force || rc=1
  run "$py" -m splatgl bench --scale --sizes 1M --sh3-sizes 1M --out "$s/b" --force || rc=1
  run "$py" -m splatgl bench --scale --sizes 3M,6M --sh3-sizes none --out "$s/c" --force || rc=1
  run "$py" -m splatgl bench --scale --sizes none --sh3-sizes 6M --width 1280 --height 720 \
    --out "$s/d" --force || rc=1
  local parts=()   # the runs that wrote their JSON
  for r in a b c d; do
    if [ "$dry" -eq 1 ] || [ -f "$s/$r/scale.json" ]; then parts+=("$s/$r/scale.json"); fi
  done
  if [ ${#parts[@]} -gt 0 ]; then
    run "$py" -m splatgl.commands._bench_tools scale-report "${parts[@]}" --out "$s" || rc=1
  fi
  return "$rc"
}
if wants scale; then
  step scale "$out/scale.txt" scale_all || true
fi

if [ "$dry" -eq 0 ]; then
  echo "== summary ($out/summary.txt)"
  cat "$out/summary.txt"
fi
exit "$failed"
