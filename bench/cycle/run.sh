#!/bin/sh
# Builds and runs the cycle engine benchmark next to cyclictest (needs root for SCHED_FIFO;
# rt-tests provides cyclictest). Arguments go to cycle_bench, e.g.
#   bench/cycle/run.sh --cycles 20000 --cpu 1 --spin-us 50 --rounds 3
# BUILD_DIR selects the build tree (default: build/ at the top of the source tree).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build=${BUILD_DIR:-$root/build}
if [ ! -f "$build/CMakeCache.txt" ]; then
  cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo
fi
cmake --build "$build" --target cycle_bench
if ! command -v cyclictest >/dev/null 2>&1; then
  echo "cyclictest not found (apt-get install rt-tests); running the engine alone" >&2
  set -- --no-cyclictest "$@"
fi
exec "$build/bench/cycle/cycle_bench" "$@"
