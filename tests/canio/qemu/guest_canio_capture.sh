#!/bin/bash
# Guest script for run-guest.sh: `ds1928ctl capture` of ds1928d on can0 (real SocketCAN, the
# kernel's CAN stack, an emulated SJA1000) against ds1928-sim canio on can1. In the guest:
#  1. the daemon becomes operational over socketcan on can0, its node configured, samples fresh;
#  2. a 5 s pcapng capture (`-w FILE --duration 5`) and a 1 s candump log (`--format candump`)
#     while it cycles, each with the daemon's reply (--json) and `status` before and after;
#  3. the candump log replayed with canplayer on vcan0 (its interface name mapped), recorded
#     there with candump -L.
# The files go to the run's work directory; the host decodes and counts them
# (host_check_capture.sh: tshark, can-utils), where tshark does not pay the TCG guest's price.
# Nothing about timing is asserted: the guest's CPU is emulated.
#
# Usage: guest_canio_capture.sh BUILD_DIR SOURCE_DIR
set -u
build=${1:?build dir}
src=${2:?source dir}
here=$src/tests/canio/qemu
config=$here/canio_guest.yaml
. "$here/guest_lib.sh"
daemon=$build/daemon/ds1928d
sim=$build/tools/ds1928-sim/ds1928-sim
ctl=$build/tools/ds1928ctl/ds1928ctl
for bin in "$daemon" "$sim" "$ctl"; do
  [ -x "$bin" ] || {
    echo "FAIL: $bin not built"
    exit 1
  }
done
out=${CANIO_WORK:?the run work directory (run-guest.sh sets it)}/capture
mkdir -p "$out" || exit 1

tmp=$(mktemp -d /tmp/canio_capture.XXXXXX)
tag=$$
pids=()
failed=0
cleanup() {
  local p
  for p in "${pids[@]}"; do kill "$p" 2> /dev/null; done
  for p in "${pids[@]}"; do wait "$p" 2> /dev/null; done
  for f in "$tmp"/*.log; do
    [ "$failed" = 0 ] && break
    echo "---- $f (tail)"
    tail -n 25 "$f"
  done
  cp "$tmp"/*.log "$out/" 2> /dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
fail() {
  echo "FAIL: $*"
  failed=1
  exit 1
}
pass() {
  local up
  read -r up _ < /proc/uptime
  echo "ok: [${up}s] $*"
}

# ---- 1. the node on can1, the daemon on can0 ----------------------------------------------------
"$sim" canio --iface can1 --node 1 --config "$config" > "$tmp/sim.log" 2>&1 &
pids+=("$!")
sim_filters() { file_has /proc/net/can/rcvlist_sff "^ +can1 " || file_has /proc/net/can/rcvlist_fil "^ +can1 "; }
until_true 60 sim_filters || fail "ds1928-sim canio registered no receive filter on can1 within 60 s"

sock=$tmp/ctl.sock
cp "$config" "$tmp/daemon.yaml"
printf 'shm:\n  name: /ds1928d_cq_capture_%s\nsocket:\n  path: %s\n' "$tag" "$sock" >> "$tmp/daemon.yaml"
"$daemon" -c "$tmp/daemon.yaml" > "$tmp/daemon.log" 2>&1 &
daemon_pid=$!
pids+=("$daemon_pid")
# status NAME: the daemon's status as shell variables (status_vars.py: one interpreter start for
# the whole test), the JSON in $out/status-NAME.json.
coproc STATUS_VARS { exec python3 "$here/status_vars.py" --serve; }
pids+=("$STATUS_VARS_PID")
status() {
  local line vars=""
  "$ctl" --json --timeout 20000 -s "$sock" status > "$out/status-$1.json" 2>> "$tmp/ctl.log" || return 1
  echo "$out/status-$1.json 0" >&"${STATUS_VARS[1]}"
  while read -r -t 60 line <&"${STATUS_VARS[0]}"; do
    [ "$line" = "#end" ] && break
    vars+="$line"$'\n'
  done
  [ "$line" = "#end" ] || fail "status_vars.py does not answer"
  eval "$vars"
}
cycling() { status start && [ "$bus_state" = operational ] && [ "$configured" = 1 ] && [ "${n_samples:-0}" -gt 10 ]; }
until_true 90 cycling || {
  kill -0 "$daemon_pid" 2> /dev/null || fail "ds1928d exited: $(tail -n 5 "$tmp/daemon.log")"
  fail "ds1928d not cycling with fresh samples within 90 s (bus state '${bus_state:-?}', configured ${configured:-?}, samples ${n_samples:-?})"
}
[ "$transport" = socketcan ] && [ "$interface" = can0 ] ||
  fail "status says $transport on $interface, expected socketcan on can0"
pass "ds1928d operational over socketcan on can0 ($bitrate bit/s), node configured, $n_samples samples"

# ---- 2. the captures ----------------------------------------------------------------------------
# capture NAME ARGS...: ds1928ctl --json capture ARGS, the reply in $out/NAME.json.
# Every process start costs seconds under TCG: status (saved, read on the host) only around the
# pcapng capture.
snapshot() {
  "$ctl" --json --timeout 20000 -s "$sock" status > "$out/status-$1.json" 2>> "$tmp/ctl.log" ||
    fail "ds1928ctl status ($1): $(tail -n 3 "$tmp/ctl.log")"
}
capture() {
  local name=$1
  shift
  [ "$name" = pcapng ] && snapshot "$name-before"
  "$ctl" --json --timeout 60000 -s "$sock" capture "$@" > "$out/$name.json" 2> "$tmp/$name.log" ||
    fail "ds1928ctl capture $*: $(cat "$tmp/$name.log")"
  [ "$name" = pcapng ] && snapshot "$name-after"
  kill -0 "$daemon_pid" 2> /dev/null || fail "ds1928d exited during the $name capture"
}
capture pcapng -w "$out/can.pcapng" --duration 5
pass "pcapng capture of 5 s: $(stat -c %s "$out/can.pcapng") bytes; reply $(cut -c1-200 "$out/pcapng.json")"
capture candump --format candump -w "$out/can.log" --duration 1
mapfile -t lines < "$out/can.log"
[ ${#lines[@]} -gt 0 ] || fail "the candump log is empty"
pass "candump log of 1 s: ${#lines[@]} lines, first: ${lines[0]}"

# ---- 3. canplayer replays the log on vcan0 ------------------------------------------------------
# candump -L records the replay into the guest's tmpfs (a write per frame to the 9p work
# directory is slow enough under TCG to overflow its socket's receive queue) with a larger receive
# buffer, and exits after as many frames as the log has or after 15 s of silence; canplayer maps
# the log's interface can0 to vcan0 and keeps the logged spacing. The guest's own kernel: its
# receive buffer limit may be raised.
echo 1048576 > /proc/sys/net/core/rmem_max
candump -L -r 1048576 -n ${#lines[@]} -T 15000 vcan0 > "$tmp/replayed.txt" 2> "$tmp/candump.log" &
candump_pid=$!
pids+=("$candump_pid")
vcan_receiver() { file_has /proc/net/can/rcvlist_all "^ +vcan0 "; }
until_true 30 vcan_receiver || fail "candump on vcan0 never registered"
canplayer -I "$out/can.log" vcan0=can0 > "$tmp/canplayer.log" 2>&1 ||
  fail "canplayer refused the log: $(cat "$tmp/canplayer.log")"
wait "$candump_pid"
cp "$tmp/replayed.txt" "$out/replayed.log"
mapfile -t replayed < "$out/replayed.log"
[ ${#replayed[@]} = ${#lines[@]} ] ||
  fail "candump -L on vcan0 saw ${#replayed[@]} of the ${#lines[@]} replayed frames"
pass "canplayer replayed the log on vcan0: candump -L saw ${#replayed[@]} frames (compared on the host)"
kill -TERM "$daemon_pid" 2> /dev/null
wait "$daemon_pid" 2> /dev/null
exit 0
