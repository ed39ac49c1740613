#!/bin/bash
# The Python package ds1928 (python/) against the running daemon on the simulated node:
# records read by ds1928.Reader equal ds1928ctl's for the same bus cycles, the futex wait wakes
# at each publication, the control client gets status, EnDat identification and precise errors,
# the time base and the isochronous loop (cycles()) read the cycle they were timed for,
# an object of another ABI version or a foreign one is refused with a message naming what
# differs, and a stopped then restarted daemon is seen (DaemonStopped, reopen()). Across that
# stop and restart also run, unchanged, the loop of python/README.md and examples/shm_reader.c:
# both carry on with the new daemon (they print its cycles) instead of exiting.
#
# Usage: python_reader_test.sh BUILD_DIR SOURCE_DIR     (root: SCHED_FIFO daemon; 77 = skipped)
set -u
build=${1:?build dir}
src=${2:?source dir}
here=$(cd "$(dirname "$0")" && pwd)
if [ "$(id -u)" != 0 ]; then echo "SKIP: needs root (the daemon's SCHED_FIFO)"; exit 77; fi
tag=$(printf '%x%x' $$ $((RANDOM % 256)))$(date +%N | cut -c1-4)
work=$(mktemp -d /tmp/ds1928-py-XXXXXX)
shm=/ds1928-py-$tag
daemon=$build/daemon/ds1928d ctl=$build/tools/ds1928ctl/ds1928ctl
dpid=""
cleanup() {
  [ -n "$dpid" ] && kill -TERM "$dpid" 2>/dev/null && timeout 10 tail --pid="$dpid" -f /dev/null
  rm -f /dev/shm"$shm" /dev/shm"$shm".wait /dev/shm"$shm"-bad*
  rm -rf "$work"
}
trap cleanup EXIT
sed -e "s|^\(  name:\) /ds1928d |\1 $shm |" \
    -e "s|^\(  path:\) /run/ds1928d/control.sock|\1 $work/control.sock|" \
    -e "s|^\(  hold_cpu_dma_latency:\) true|\1 false|" \
    "$src/config/simulated.yaml" > "$work/daemon.yaml"
start_daemon() {
  dpid=$(python3 "$src/tests/deploy/notify_start.py" "$work" 60 "$work/daemon.log" -- \
           "$daemon" --config "$work/daemon.yaml")
  [ -n "$dpid" ] || { echo "FAIL: the daemon did not start"; cat "$work/daemon.log"; exit 1; }
}
start_daemon
export PYTHONPATH=$src/python
# Python and ds1928ctl follow the same publications for a second.
timeout 20 "$ctl" --shm "$shm" --json position --axis 0 --follow --count 1500 >"$work/ctl.json" &
ctlpid=$!
python3 "$here/python_reader_check.py" live "$shm" "$work/control.sock" "$work/py.json" || fail=1
wait $ctlpid
python3 "$here/python_reader_check.py" compare "$work/py.json" "$work/ctl.json" || fail=1
python3 "$here/python_reader_check.py" abi "$shm-bad" || fail=1
python3 "$here/python_reader_check.py" timebase "$shm" || fail=1
# The README's loop (the first python block of python/README.md, on this daemon's memory) and the
# C example (5000 publications: several seconds, so that the stop below comes in the middle).
awk '/^```python/{on=1; next} /^```/{if (on) exit} on' "$src/python/README.md" |
  sed "s|\"/ds1928d\"|\"$shm\"|" >"$work/readme_loop.py"
grep -q "Reader(\"$shm\")" "$work/readme_loop.py" || { echo "FAIL: no loop in python/README.md"; exit 1; }
python3 -u "$work/readme_loop.py" >"$work/loop.out" 2>"$work/loop.err" &
looppid=$!
"$build/examples/ds1928_shm_reader_c" "$shm" 0 1 5000 >"$work/c.out" 2>"$work/c.err" &
cpid=$!
# Each has printed (the loop: "cycle position valid" lines; the C reader: its header line).
for _ in $(seq 200); do
  [ "$(grep -c '^[0-9]* ' "$work/loop.out")" -gt 1 ] && grep -q "generation" "$work/c.out" && break
  sleep 0.05
done
last_before=$(grep '^[0-9]* ' "$work/loop.out" | tail -n 1 | cut -d' ' -f1)
[ -n "$last_before" ] || { echo "FAIL: the README loop printed nothing: $(cat "$work/loop.err")"; fail=1; }
# Stop and restart under a reader.
python3 "$here/python_reader_check.py" restart "$shm" "$work/restart.flag" &
reader=$!
for _ in $(seq 100); do [ -f "$work/restart.flag" ] && break; sleep 0.05; done
kill -TERM "$dpid"; timeout 20 tail --pid="$dpid" -f /dev/null; dpid=""
start_daemon
wait $reader || fail=1
# The README loop: still running, and printing the new daemon's cycles (which start again near
# 0, below the last one of the stopped daemon).
after=""
for _ in $(seq 400); do
  after=$(awk -v b="${last_before:-0}" 'seen && $1 + 0 < b {print; exit} $1 == b {seen=1}' "$work/loop.out")
  [ -n "$after" ] && break
  kill -0 "$looppid" 2>/dev/null || break
  sleep 0.05
done
if kill -0 "$looppid" 2>/dev/null && [ -n "$after" ]; then
  echo "ok:   the README loop follows a normal stop: last cycle $last_before, then the new daemon's $(cut -d' ' -f1 <<<"$after")"
else
  echo "FAIL: the README loop did not follow the restart: $(tail -n 3 "$work/loop.out") $(cat "$work/loop.err")"
  fail=1
fi
kill "$looppid" 2>/dev/null; wait "$looppid" 2>/dev/null
# The C example: waits for the new daemon and completes its 5000 publications.
crc=timeout
if timeout 30 tail --pid="$cpid" -f /dev/null; then wait "$cpid"; crc=$?; else kill "$cpid"; wait "$cpid"; fi
if [ "$crc" = 0 ] && grep -q "daemon stopped; waiting" "$work/c.err" &&
   grep -q "daemon restarted: generation" "$work/c.out"; then
  echo "ok:   examples/shm_reader.c follows a normal stop: $(grep -c '^cycle' "$work/c.out") publications, $(grep restarted "$work/c.out")"
else
  echo "FAIL: shm_reader (exit $crc) did not follow the stop and restart: $(cat "$work/c.err") $(tail -n 2 "$work/c.out")"
  fail=1
fi
exit ${fail:-0}
