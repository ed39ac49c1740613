#!/bin/sh
# Runs every benchmark once, each printing its figures next to its baseline.
#   bench/run-all.sh [BUILD_DIR]        (make bench)
# Needs root for SCHED_FIFO, raw sockets and network namespaces; takes about 10 minutes.
# Pass QUICK=1 for a short smoke run of each (figures are then only indicative).
set -u
build=$(cd "${1:-build}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
quick=${QUICK:-0}
status=0
run() {
  echo
  echo "==== $*"
  "$@" || { echo "==== FAILED: $*"; status=1; }
}
if [ "$quick" = 1 ]; then
  run env BUILD_DIR="$build" "$here/cycle/run.sh" --cycles 5000
  run "$build/bench/shm/shm_bench"
  run "$build/bench/flatstream/flatstream_bench" --quick
  run "$build/bench/endat/endat_bench"
  run "$here/powerlink/run_rx_latency.sh" "$build" 5000
  run "$here/powerlink/run_cycle_bench.sh" "$build" --quick --nodes 1
  run "$build/bench/canio/canio_bench" --quick
  [ -f "$build/linuxcnc/ds1928.so" ] && run "$here/consumers/run_age_bench.sh" "$build" 1
  run env BUILD_DIR="$build" "$here/capture/flight_recorder.sh" both 3 1
else
  run env BUILD_DIR="$build" "$here/cycle/run.sh" --cycles 20000 --rounds 3
  run "$build/bench/shm/shm_bench"
  run "$build/bench/flatstream/flatstream_bench"
  run "$build/bench/endat/endat_bench"
  run "$here/powerlink/run_rx_latency.sh" "$build" 20000
  run "$here/powerlink/run_cycle_bench.sh" "$build" --nodes "1 4 16"
  run "$build/bench/canio/canio_bench"
  [ -f "$build/linuxcnc/ds1928.so" ] && run "$here/consumers/run_age_bench.sh" "$build" 3
  run env BUILD_DIR="$build" "$here/capture/flight_recorder.sh" both 10 3
fi
exit $status
