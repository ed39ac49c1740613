#!/bin/bash
# Phase of a control application against the bus, side by side in one run: the daemon on the
# simulated node at 1 ms and at 250 µs, an application cycle of 1 ms, STARTS starts of SECONDS
# each (a new LinuxCNC and new readers per start; the daemon keeps running):
#   (a) free   LinuxCNC's 1 ms servo thread, free-running (ds1928, sync=0): its age-us pin;
#   (b) locked the same thread with `loadrt ds1928 sync=1` (RTAPI task PLL): age-us, the phase
#              error (sync-error-us) after the lock, and the lock-in time (periods from
#              `halcmd start` to sync-locked, sampled in the thread);
#   (c) wait   a reader sleeping on the futex for every publication of a multiple of 1 ms;
#   (d) iso    a reader timed on the published time base: clock_nanosleep(TIMER_ABSTIME) to the
#              next such publication + OFFSET_US.
# (a), (c) and (d) run at the same time, (b) after them. age = the consumer's CLOCK_MONOTONIC at
# the read − the position's acquisition (pos_time_ns). Prints per start and consumer p1/p50/p99/max
# in µs, the range of p50 across the starts, and the locked thread's phase error and lock-in.
#
#   bench/consumers/run_sync_bench.sh [BUILD_DIR] [SECONDS] [STARTS] [OFFSET_US]
#   (root, linuxcnc-uspace; defaults 10 s, 5 starts, 50 µs)
set -u
build=$(cd "${1:-build}" && pwd)
seconds=${2:-10}
starts=${3:-5}
offset_us=${4:-50}
src=$(cd "$(dirname "$0")/../.." && pwd)
module=$build/linuxcnc/ds1928.so
reader=$build/bench/consumers/ds1928_reader_age
[ "$(id -u)" = 0 ] || { echo "needs root"; exit 1; }
[ -f "$module" ] || { echo "$module not built (linuxcnc-uspace-dev)"; exit 1; }
. "$src/tests/lib/linuxcnc.sh"
linuxcnc_enter_namespaces "$0" "$@"

work=$(mktemp -d /tmp/ds1928-syncb-XXXXXX)
shm=/ds1928-syncb-$$-$RANDOM
dpid=""
cleanup() {
  linuxcnc_stop
  ds1928_daemon_stop TERM
  rm -f /dev/shm"$shm" /dev/shm"$shm".wait
  linuxcnc_teardown "$work" && rm -rf "$work"
}
trap cleanup EXIT
linuxcnc_setup "$work" "$module" || exit 1
n=$((seconds * 1000))

# servo SYNC CFG PINS...: LinuxCNC with a 1 ms servo thread, ds1928 (sync=SYNC) and a sampler
# of PINS started before the thread, so that the first period is sampled too.
servo() {
  local sync=$1 cfg=$2 i=0 p
  shift 2
  linuxcnc_start >"$work/rt.log" 2>&1 || { cat "$work/rt.log"; return 1; }
  halcmd loadrt threads name1=servo period1=1000000 &&
    halcmd loadrt ds1928 shm="$shm" axes=x sync=$sync &&
    halcmd loadrt sampler depth=$((n + 4000)) cfg=$cfg &&
    halcmd addf ds1928.read servo && halcmd addf sampler.0 servo || return 1
  for p in "$@"; do halcmd net "s$i" "ds1928.$p" "sampler.0.pin.$i" || return 1; i=$((i + 1)); done
}

results=$work/results.txt
: >"$results"
for period_us in 1000 250; do
  every=$((1000 / period_us))
  ds1928_daemon_configure "$work" "$shm" "$period_us" || exit 1
  ds1928_daemon_start "$build" "$src" "$work" || exit 1
  sleep 2  # the daemon's first measurement windows
  for s in $(seq "$starts"); do
    # (a) + (c) + (d)
    servo 0 bf x.valid x.age-us && halcmd start || exit 1
    hal_wait_pin ds1928.x.valid TRUE 10 >/dev/null || exit 1
    "$reader" "$shm" wait "$every" 0 "$seconds" >"$work/c.txt" &
    rc=$!
    "$reader" "$shm" iso "$every" "$offset_us" "$seconds" >"$work/d.txt" &
    rd=$!
    halsampler -c 0 -n "$n" >"$work/a.txt"
    wait $rc $rd
    linuxcnc_stop
    # (b): sampled from the thread's first period (lock-in), then SECONDS of lock
    servo 1 bffbf x.valid x.age-us sync-error-us sync-locked phase-us || exit 1
    halcmd start || exit 1
    halsampler -c 0 -n $((n + 3000)) >"$work/b.txt"
    linuxcnc_stop
    python3 - "$period_us" "$s" "$work" "$offset_us" >>"$results" <<'PY'
import sys
period_us, start, work, offset_us = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3], sys.argv[4]
pick = lambda a, q: a[min(len(a) - 1, int(q * len(a)))]
def row(name, ages):
    ages = sorted(ages)
    return f"{period_us} {start} {name} {len(ages)} {pick(ages, .01):.1f} {pick(ages, .5):.1f} {pick(ages, .99):.1f} {ages[-1]:.1f}"
a = [float(l.split()[1]) for l in open(f"{work}/a.txt") if l.split()[:1] == ["1"]]
print(row("a-free", a))
rows = [l.split() for l in open(f"{work}/b.txt")]
lock = next((i for i, r in enumerate(rows) if r[3] == "1"), None)
after = rows[lock:] if lock is not None else []
b = [float(r[1]) for r in after if r[0] == "1"]
print(row("b-locked", b) if b else f"{period_us} {start} b-locked 0 0 0 0 0")
err = sorted(abs(float(r[2])) for r in after) or [0.0]
unlocked = sum(r[3] != "1" for r in after)
print(f"{period_us} {start} b-phase {len(after)} lockin_ms {lock if lock is not None else -1} "
      f"err_p50 {pick(err, .5):.2f} err_p99 {pick(err, .99):.2f} err_max {err[-1]:.2f} unlocked {unlocked}")
for mode, f in (("c-wait", "c.txt"), ("d-iso", "d.txt")):
    w = open(f"{work}/{f}").read().split()
    n = int(w[1]); p1, p50, p99, mx = (float(x) / 1000 for x in w[2:6])
    print(f"{period_us} {start} {mode} {n} {p1:.1f} {p50:.1f} {p99:.1f} {mx:.1f}" +
          (f" timed {w[6]}" if mode == "d-iso" else ""))
PY
    tail -5 "$results"
  done
  ds1928_daemon_stop TERM
done
echo
echo "Age of the position at the read, µs ($starts starts of $seconds s; simulated node, $(nproc) CPUs, $(uname -r), load $(cut -d' ' -f1-3 /proc/loadavg))"
python3 - "$results" <<'PY'
import sys, collections
rows = [l.split() for l in open(sys.argv[1]) if l.strip()]
print("| bus | consumer | start | reads | p1 | p50 | p99 | max |")
print("|---:|---|---:|---:|---:|---:|---:|---:|")
p50s = collections.defaultdict(list)
for r in rows:
    if r[2] == "b-phase":
        continue
    print(f"| {r[0]} µs | {r[2]} | {r[1]} | {r[3]} | {r[4]} | {r[5]} | {r[6]} | {r[7]} |")
    p50s[(r[0], r[2])].append(float(r[5]))
print()
print("| bus | consumer | p50 across starts (min – max) | range |")
print("|---:|---|---|---:|")
for (bus, name), v in p50s.items():
    print(f"| {bus} µs | {name} | {min(v):.1f} – {max(v):.1f} | {max(v) - min(v):.1f} |")
print()
print("| bus | start | locked periods | lock-in (ms) | phase error p50 / p99 / max µs | unlocked after lock |")
print("|---:|---:|---:|---:|---|---:|")
for r in rows:
    if r[2] == "b-phase":
        print(f"| {r[0]} µs | {r[1]} | {r[3]} | {r[5]} | {r[7]} / {r[9]} / {r[11]} | {r[13]} |")
PY
