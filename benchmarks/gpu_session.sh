#!/usr/bin/env bash
# The checks a session runs on a lent GPU machine, as one prepared command (device time is
# short: each phase has its own time limit). Run from the project root there, after
#   ../shared/gpu/prepare.sh                     (on the CPU machine: packs .gpu/)
# with carry [".gpu"] and the command
#   source .gpu/setup.sh; bash benchmarks/gpu_session.sh [tests] [bench]
# Logs go to $OUT/logs (the device tool's $OUT, else out/gpu), packed into $OUT/gpu_logs.tar.gz;
# a summary is printed at the end.
#   tests: the quick suite on CUDA (pytest-xdist, 12 workers; a crashed worker is reported
#          and replaced; each failure's traceback goes to logs/failures.txt at once) beside
#          benchmarks/triage_backend.py (default flags, and direct/whitted under every flag set);
#   bench: bench_cornell, bench_scenes, bench_optim and bench_volpath at GPU sizes, alone;
#   profile: benchmarks/profile_kernels.py on the scenes where pbr lost most (kernels,
#          registers and spills by ptxas, Dr.Jit flag changes).
# Measured on an H100 (2026-11-27): the suite needs more than 330 s with 12 workers (the
# forward==reverse tests over every parameter take longest); the benchmarks about 250 s.
set -u
# Phases run in the order given: tests, bench, profile (default: tests bench). Environment:
#   TEST_S      seconds for the test phase (default 330)
#   NWORKERS    pytest-xdist workers (default 12)
#   PYTEST_ARGS what pytest runs (default: tests, and then the triage runs beside it)
#   BENCHES     which benchmarks (default: cornell scenes optim volpath)
#   SCENES_ARGS bench_scenes' scene choice (default --quick; empty: all 31), SCENES_S its limit (240 s)
#   PROFILE_SCENES profile_kernels' scenes (default door,cornell,caustic: the scenes above 1.0x
#               on the H200; registers by ptxas without Dr.Jit's enable_smem_spilling pragma)
#   PROFILE_ABLATE its --ablate changes (default gathered-area-light: whether the 13 light
#               values live across every trace of a one-light scene cost time on the GPU)
phases=${*:-tests bench}
test_s=${TEST_S:-330}
OUT=${OUT:-out/gpu}
L=$OUT/logs
mkdir -p "$L"
export PBR_TEST_BACKEND=cuda PYTHONUNBUFFERED=1 PBR_FAILURE_LOG=$L/failures.txt PBR_DURATION_LOG=$L/durations.txt
py=python3
t0=$(date +%s)
stamp() { echo "[$(( $(date +%s) - t0 )) s] $*"; }

{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
  $py -c "import sys, drjit, mitsuba; print(sys.version.split()[0], 'drjit', drjit.__version__, 'mitsuba', mitsuba.__version__)"
} > "$L/env.txt" 2>&1

bench() {   # name, limit (s), script and arguments
  local name=$1 limit=$2; shift 2
  stamp "start $name"
  timeout "$limit" $py "$@" --backend cuda > "$L/$name.txt" 2>&1; echo "rc $?" >> "$L/$name.txt"
}

for phase in $phases; do
  case $phase in
  tests)
    stamp "start tests"
    # A test over --timeout is stopped with its stack (thread method: the worker exits and
    # xdist reports it), so pytest ends inside the phase and prints its summary.
    # worksteal (pytest-xdist >= 3.2): an idle worker takes tests queued on a busy one
    # (with 'load', 58 gradient tests waited behind long ones until the time ran out)
    dist=$($py -c 'import xdist; v = tuple(int(x) for x in xdist.__version__.split(".")[:2]); print("worksteal" if v >= (3, 2) else "load")' 2>/dev/null || echo load)
    timeout "$test_s" $py -m pytest -v -n ${NWORKERS:-12} --dist $dist -p no:cacheprovider --timeout $(( test_s * 3 / 4 )) \
      --timeout-method thread --tb=short -rfE --durations=25 ${PYTEST_ARGS:-tests} > "$L/pytest.txt" 2>&1 &
    if [ -z "${PYTEST_ARGS:-}" ]; then
      ( timeout "$test_s" $py benchmarks/triage_backend.py --backend cuda --timeout 120 --out "$L/triage.json" \
          > "$L/triage.txt" 2>&1
        timeout 60 $py benchmarks/triage_backend.py --backend cuda --cases direct,whitted --flags all --timeout 60 \
          --out "$L/triage_flags.json" > "$L/triage_flags.txt" 2>&1 ) &
    fi
    wait ;;
  bench)
    for b in ${BENCHES:-cornell scenes optim volpath}; do
      case $b in
      cornell) bench bench_cornell 90 benchmarks/bench_cornell.py --res 1024 --spp 256 --reps 3 ;;
      scenes) bench bench_scenes ${SCENES_S:-240} benchmarks/bench_scenes.py --res 512 --spp 64 --reps 3 ${SCENES_ARGS---quick} ;;
      optim) bench bench_optim 80 benchmarks/bench_optim.py --res 1024 --spp 16 --reps 5 --no-children ;;
      volpath) bench bench_volpath 80 benchmarks/bench_volpath.py --res 512 --spp 64 --ref-spp 1024 --reps 3 ;;
      esac
    done ;;
  profile)
    bench profile_kernels 200 benchmarks/profile_kernels.py --res 1024 --spp 64 --reps 3 \
      --scenes ${PROFILE_SCENES:-door,cornell,caustic} --ir-dir "$L/ir" --ablate ${PROFILE_ABLATE:-gathered-area-light} ;;
  esac
done
stamp "done"
tar czf "$OUT/gpu_logs.tar.gz" -C "$OUT" logs
echo "===== summary"
cat "$L/env.txt"
for f in "$L"/bench_*.txt "$L"/profile_*.txt "$L"/triage*.txt; do
  [ -f "$f" ] && { echo "== $(basename "$f")"; grep -v '^\s*$' "$f" | tail -n 14; }
done
if [ -f "$L/pytest.txt" ]; then
  echo "== pytest"
  grep -E "^(FAILED|ERROR) |crashed|[0-9]+ (passed|failed)" "$L/pytest.txt" | tail -n 60
fi
[ -f "$L/failures.txt" ] && { echo "== failures (first lines; all of them in failures.txt)"; head -c 6000 "$L/failures.txt"; }
