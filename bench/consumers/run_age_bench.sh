#!/bin/bash
# How old is the position when the consumer uses it? For the daemon on the simulated node at
# 1 ms and at its shortest period (100 µs), side by side in the same run:
#   waiting   a reader that sleeps on the futex for every publication (ds1928_shm_wait), then
#             reads (bench/consumers/wait_age.c);
#   HAL 1 kHz LinuxCNC's free-running 1 ms servo thread with the ds1928 component (its age-us
#             pin, sampled in the thread by `sampler`).
# age = consumer's CLOCK_MONOTONIC at the read − the position's acquisition time (pos_time_ns).
# Prints p50 / p99 / max in µs and as a ratio to the bus period.
#
#   bench/consumers/run_age_bench.sh [BUILD_DIR] [SECONDS]     (root, linuxcnc-uspace)
set -u
build=$(cd "${1:-build}" && pwd)
seconds=${2:-3}
src=$(cd "$(dirname "$0")/../.." && pwd)
module=$build/linuxcnc/ds1928.so
[ "$(id -u)" = 0 ] || { echo "needs root"; exit 1; }
[ -f "$module" ] || { echo "$module not built (linuxcnc-uspace-dev)"; exit 1; }
. "$src/tests/lib/linuxcnc.sh"
linuxcnc_enter_namespaces "$0" "$@"

work=$(mktemp -d /tmp/ds1928-age-XXXXXX)
shm=/ds1928-age-$$-$RANDOM
dpid=""
cleanup() {
  linuxcnc_stop
  ds1928_daemon_stop TERM
  rm -f /dev/shm"$shm" /dev/shm"$shm".wait
  linuxcnc_teardown "$work" && rm -rf "$work"
}
trap cleanup EXIT
linuxcnc_setup "$work" "$module" || exit 1

rows=()
for period_us in 1000 100; do
  ds1928_daemon_configure "$work" "$shm" "$period_us" || exit 1
  ds1928_daemon_start "$build" "$src" "$work" || exit 1
  linuxcnc_start >"$work/rt.log" 2>&1 || { cat "$work/rt.log"; exit 1; }
  halcmd loadrt ds1928 shm="$shm" axes=x && halcmd loadrt threads name1=servo period1=1000000 &&
    halcmd loadrt sampler depth=$((seconds * 1000 + 1000)) cfg=bf &&
    halcmd addf ds1928.read servo && halcmd addf sampler.0 servo &&
    halcmd net v ds1928.x.valid sampler.0.pin.0 && halcmd net a ds1928.x.age-us sampler.0.pin.1 &&
    halcmd start || exit 1
  hal_wait_pin ds1928.x.valid TRUE 10 || exit 1
  halsampler -c 0 -n $((seconds * 1000)) >"$work/hal.txt" &
  sampler=$!
  waiting=$("$build/bench/consumers/ds1928_wait_age" "$shm" $((seconds * 1000000 / period_us)))
  wait $sampler
  rows+=("$(python3 - "$period_us" "$waiting" "$work/hal.txt" <<'PY'
import sys
period_us = float(sys.argv[1])
w = sys.argv[2].split()
n, p50, p99, mx = int(w[1]), *(float(x) / 1000 for x in w[2:5])
ages = sorted(float(line.split()[1]) for line in open(sys.argv[3]) if line.split()[:1] == ["1"])
pick = lambda q: ages[min(len(ages) - 1, int(q * len(ages)))]
def row(name, n, a, b, c):
    return (f"| {period_us:6.0f} µs | {name:18s} | {n:6d} | {a:8.1f} | {b:8.1f} | {c:8.1f} | "
            f"{a / period_us:5.2f} | {b / period_us:5.2f} | {c / period_us:6.2f} |")
print(row("waiting (futex)", n, p50, p99, mx))
print(row("HAL servo 1 kHz", len(ages), pick(0.5), pick(0.99), ages[-1]))
PY
)")
  linuxcnc_stop
  ds1928_daemon_stop TERM
done
echo "Age of the position at the consumer's read (simulated node, $(nproc) CPUs, $(uname -r))"
echo "| bus period | consumer           |  reads | p50 µs   | p99 µs   | max µs   | p50/T | p99/T | max/T  |"
echo "|-----------:|--------------------|-------:|---------:|---------:|---------:|------:|------:|-------:|"
printf '%s\n' "${rows[@]}"
