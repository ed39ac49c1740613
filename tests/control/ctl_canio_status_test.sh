#!/bin/bash
# `ds1928ctl status` against the real daemon on the CAN-I/O bus (the virtual bus and ds1928-sim
# canio, as `make run-canio`): the CANopen node's own fields — NMT state, heartbeat, boot-ups —
# and each axis' sampling (samples counting, missing, late), no POWERLINK fields; `status --check`
# exits 0 when every axis of its reply is valid, else 5 (also once the node is gone). The node's
# first samples are logged as its first contact, not as a return or a reset; when the node comes
# back after it was gone, "answering again". The module state like its r-LED follows: run while
# the node delivers, off once it is gone (no heartbeat watched: its samples stopped), run again.
#
# Usage: ctl_canio_status_test.sh BUILD_DIR SOURCE_DIR     (root: SCHED_FIFO daemon; 77 = skipped)
set -u
build=${1:?build dir}
src=${2:?source dir}
if [ "$(id -u)" != 0 ]; then echo "SKIP: needs root (the daemon's SCHED_FIFO)"; exit 77; fi
tag=$(printf '%x' $$)$(date +%N | cut -c1-4)
work=$(mktemp -d /tmp/ds1928-ctlcan-XXXXXX)
shm=/ds1928-ctlcan-$tag vbus=ds1928-ctlcan-$tag
daemon=$build/daemon/ds1928d ctl=$build/tools/ds1928ctl/ds1928ctl sim=$build/tools/ds1928-sim/ds1928-sim
dpid="" spid=""
cleanup() {
  [ -n "$dpid" ] && kill -TERM "$dpid" 2>/dev/null && timeout 10 tail --pid="$dpid" -f /dev/null
  [ -n "$spid" ] && kill -TERM "$spid" 2>/dev/null && timeout 10 tail --pid="$spid" -f /dev/null
  rm -f /dev/shm"$shm" /dev/shm"$shm".wait /dev/shm/ds1928-vcan."$vbus"
  rm -rf "$work"
}
trap cleanup EXIT
fail() { echo "FAIL: $*"; echo "--- status:"; cat "$work/status.txt" 2>/dev/null; exit 1; }
sed -e "s|^\(  virtual_bus:\) ds1928-sim |\1 $vbus |" \
    -e "s|^\(  name:\) /ds1928d-canio|\1 $shm|" \
    -e "s|^\(  path:\) /run/ds1928d/canio.sock|\1 $work/control.sock|" \
    -e "s|^\(  listen:\) 127.0.0.1:9929|\1 off|" \
    "$src/config/canio-sim.yaml" >"$work/daemon.yaml"
grep -q "virtual_bus: $vbus " "$work/daemon.yaml" && grep -q "name: $shm" "$work/daemon.yaml" &&
  grep -q "path: $work/control.sock" "$work/daemon.yaml" &&
  grep -q "listen: off" "$work/daemon.yaml" || fail "could not derive the configuration"
"$sim" canio --virtual "$vbus" --config "$work/daemon.yaml" >"$work/sim.log" 2>&1 &
spid=$!
dpid=$(python3 "$src/tests/deploy/notify_start.py" "$work" 60 "$work/daemon.log" -- \
         "$daemon" --config "$work/daemon.yaml") || { cat "$work/daemon.log" "$work/sim.log"; fail "the daemon did not start"; }
export DS1928_SOCKET=$work/control.sock
# Samples flow: wait until the axis is valid (bounded; the daemon is READY after its first
# exchange, the node's configuration follows). --check's verdict is the reply's own: on a loaded
# machine the axis may drop to stale between two requests, so each verdict is compared with the
# states in the same reply.
valid_seen=0
for _ in $(seq 200); do
  rc=0; "$ctl" --json status --check >"$work/check.json" 2>/dev/null || rc=$?
  bad=$(jq '[.axes[] | select(.state != "valid")] | length' "$work/check.json")
  { [ $rc = 0 ] && [ "$bad" = 0 ]; } || { [ $rc = 5 ] && [ "$bad" -gt 0 ]; } ||
    fail "status --check exit $rc with $bad axes not valid in its reply"
  [ $rc = 0 ] && { valid_seen=1; break; }
  sleep 0.05
done
[ $valid_seen = 1 ] || fail "the axis never became valid (status --check never exited 0)"
"$ctl" status >"$work/status.txt" 2>&1 || fail "status exit $?"
grep -q "bus:       canio, " "$work/status.txt" || fail "no canio bus line"
grep -Eq "^    interface $vbus \(virtual\), " "$work/status.txt" || fail "no interface line"
grep -Eq "^    node 1: NMT [a-z_-]+, (heartbeats [0-9]+ \([0-9]+ missed\)|heartbeat not watched), boot-ups [0-9]+, EMCY [0-9]+$" \
  "$work/status.txt" || fail "no CANopen node line"
samples=$(sed -n 's/^      axis 0: .*, samples \([0-9]*\), missing [0-9]*, late [0-9]*$/\1/p' "$work/status.txt")
[ -n "$samples" ] && [ "$samples" -gt 0 ] || fail "no axis line with samples"
grep -q "PRes\|NMT ?" "$work/status.txt" && fail "POWERLINK fields on a CAN-I/O bus"
[ "$(jq -r '.axes[0].module_state' "$work/check.json")" = run ] ||
  fail "a valid axis whose module is not run: $(jq -c '.axes[0]' "$work/check.json")"
grep -Eq "^    0   axis0 +valid +module run " "$work/status.txt" || fail "no module state in the axis line"
# The node's first contact is no reset and no return: "answering (first samples)" only.
grep -q "canio node 1: axis 'axis0' answering (first samples)" "$work/daemon.log" ||
  fail "no first-contact line: $(grep 'canio node' "$work/daemon.log")"
grep -Eq "answering again|boot-up \(the node reset" "$work/daemon.log" &&
  fail "the first contact logged as a return or a reset: $(grep 'canio node' "$work/daemon.log")"
echo "ok:   CAN-I/O status: $(grep -E '^    (node|interface)|^      axis' "$work/status.txt" | tr -s ' ' | paste -sd'|')"
# The node goes away: the axis leaves valid, --check says so with 5.
kill -TERM "$spid"; timeout 10 tail --pid="$spid" -f /dev/null; spid=""
rc=0
for _ in $(seq 200); do rc=0; "$ctl" status --check >"$work/check.txt" 2>&1 || rc=$?; [ $rc = 5 ] && break; sleep 0.05; done
[ $rc = 5 ] || fail "status --check exit $rc after the node went away: $(cat "$work/check.txt")"
echo "ok:   status --check exits 5 once the node is gone: $(grep 'not valid' "$work/check.txt")"
module=""
for _ in $(seq 200); do
  module=$("$ctl" --json status | jq -r '.axes[0].module_state + " " + .axes[0].module.node_phase')
  [ "$module" = "off unknown" ] && break; sleep 0.05
done
[ "$module" = "off unknown" ] || fail "the module of a node gone is '$module', not off"
echo "ok:   the module of the node gone: $module"
# The node comes back (a power cycle): now it is a reset and a return, and logged as such.
"$sim" canio --virtual "$vbus" --config "$work/daemon.yaml" >"$work/sim2.log" 2>&1 &
spid=$!
rc=5
for _ in $(seq 400); do rc=0; "$ctl" status --check >/dev/null 2>&1 || rc=$?; [ $rc = 0 ] && break; sleep 0.05; done
[ $rc = 0 ] || fail "the axis did not become valid again after the node came back"
for _ in $(seq 100); do
  module=$("$ctl" --json status | jq -r '.axes[0].module_state'); [ "$module" = run ] && break
  sleep 0.05
done
[ "$module" = run ] || fail "the module of the node back is '$module', not run"
# The log line follows the axis' validity (the service logs node events every 10 ms, the
# journal is written off the cycle): waited for, not read at once.
for _ in $(seq 100); do grep -q "canio node 1: axis 'axis0' answering again" "$work/daemon.log" && break; sleep 0.05; done
grep -q "canio node 1: axis 'axis0' answering again" "$work/daemon.log" ||
  fail "the return is not logged as 'answering again': $(grep 'canio node' "$work/daemon.log")"
echo "ok:   the node's return: $(grep -E "canio node 1: (boot-up|axis 'axis0' answering again)" "$work/daemon.log" | cut -c25- | paste -sd'|')"
