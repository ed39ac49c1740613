#!/bin/bash
# The Python package ds1928 (python/) against the running daemon on the simulated node:
# records read by ds1928.Reader equal ds1928ctl's for the same bus cycles, the futex wait wakes
# at each publication, the control client gets status, EnDat identification and precise errors,
# the time base and the isochronous loop (cycles()) read the cycle they were timed for,
# an object of another ABI version or a foreign one is refused with a message naming what
# differs, and a stopped then restarted daemon is seen (DaemonStopped, reopen()).
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
# Stop and restart under a reader.
python3 "$here/python_reader_check.py" restart "$shm" "$work/restart.flag" &
reader=$!
for _ in $(seq 100); do [ -f "$work/restart.flag" ] && break; sleep 0.05; done
kill -TERM "$dpid"; timeout 20 tail --pid="$dpid" -f /dev/null; dpid=""
start_daemon
wait $reader || fail=1
exit ${fail:-0}
