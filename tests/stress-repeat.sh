#!/bin/bash
# The whole test suite RUNS times in a row while `stress-ng --cpu 2` keeps two CPUs busy at
# normal priority: a test that depends on scheduling luck fails here sooner or later.
#   tests/stress-repeat.sh [BUILD_DIR [RUNS]]        (make stress; RUNS defaults to 20)
# Extra ctest arguments go in CTEST_ARGS (e.g. CTEST_ARGS="-R queues" for a quick look).
# Prints one line per run and a summary; exit status 1 when any run failed. Logs of failed runs
# are kept in the directory it names.
set -u
build=${1:-build}
runs=${2:-20}
command -v stress-ng >/dev/null || { echo "stress-ng is missing: apt-get install stress-ng"; exit 2; }
[ -f "$build/CTestTestfile.cmake" ] || { echo "$build is not a configured build directory"; exit 2; }
logs=$(mktemp -d "${TMPDIR:-/tmp}/ds1928-stress.XXXXXX")

stress-ng --cpu 2 --timeout 0 --quiet &
stress_pid=$!
trap 'kill "$stress_pid" 2>/dev/null; wait "$stress_pid" 2>/dev/null' EXIT
trap 'exit 1' INT TERM

# The names ctest lists under "The following tests FAILED:" (a tab, number, " - ", name, status).
failed_tests() {
  awk '/The following tests FAILED/ { f = 1; next }
       f && /^[[:space:]]+[0-9]+ - / { sub(/^[[:space:]]+[0-9]+ - /, ""); sub(/ \([^)]*\)$/, "");
                                       printf "%s; ", $0 }' "$1"
}

failed_runs=0
start=$(date +%s)
for ((run = 1; run <= runs; run++)); do
  t0=$(date +%s)
  # shellcheck disable=SC2086
  if (cd "$build" && ctest --output-on-failure --timeout 900 -j 2 ${CTEST_ARGS:-}) \
      >"$logs/run$run.log" 2>&1; then
    echo "run $run/$runs: passed ($(($(date +%s) - t0)) s, $(grep -o 'tests passed.*' "$logs/run$run.log" | head -n1 || true))"
    rm -f "$logs/run$run.log"
  else
    failed_runs=$((failed_runs + 1))
    echo "run $run/$runs: FAILED ($(($(date +%s) - t0)) s): $(failed_tests "$logs/run$run.log")"
  fi
done
echo "$runs runs of the test suite under stress-ng --cpu 2: $failed_runs failed ($(($(date +%s) - start)) s)"
if [ "$failed_runs" -gt 0 ]; then
  echo "logs of the failed runs: $logs"
  exit 1
fi
rmdir "$logs"
