#!/bin/bash
# Host half of the guest capture test (run-guest.sh --host-check): checks what
# guest_canio_capture.sh left in WORK_DIR/capture with the host's tools, at native speed.
#  1. the 5 s pcapng capture: tshark decodes every frame as SocketCAN, none malformed, counts and
#     directions equal to the daemon's reply per interface, the Interface Statistics Blocks too
#     (tests/capture/check_can_capture.sh, as on the virtual bus);
#  2. the window against the daemon's `status` taken before and after the capture: the capture
#     points' frame numbers bracket the window, the cycle port's socket counters grew by at least
#     the frames captured in each direction;
#  3. the candump log: one can-utils log line per frame of the reply, read by log2asc, and the
#     canplayer replay on vcan0 the same frames in the same order.
#
# Usage: host_check_capture.sh WORK_DIR      (exit 0 pass, 1 fail, 77 a tool missing)
set -u
work=${1:?work dir}
d=$work/capture
here=$(cd "$(dirname "$0")" && pwd)
check=$here/../../capture/check_can_capture.sh
fail() {
  echo "FAIL: $*"
  exit 1
}
command -v jq > /dev/null || {
  echo "SKIP: jq not installed"
  exit 77
}
for f in can.pcapng pcapng.json can.log candump.json replayed.log status-pcapng-before.json status-pcapng-after.json; do
  [ -f "$d/$f" ] || fail "the guest left no $f in $d"
done

# ---- 1 ------------------------------------------------------------------------------------------
# 10 ms cycle: SYNC, an output and two inputs per cycle; the TCG guest misses cycles, so the floor
# is low. It only says the capture is not nearly empty; the counts are checked exactly.
"$check" pcapng "$d/can.pcapng" "$d/pcapng.json" 400 || exit $?

# ---- 2 ------------------------------------------------------------------------------------------
last() { tail -n 1 "$1"; }
before=$(last "$d/status-pcapng-before.json")
after=$(last "$d/status-pcapng-after.json")
r=$(jq -c .capture "$d/pcapng.json")
n=$(jq '.interfaces | length' <<< "$r")
for ((i = 0; i < n; i++)); do
  w=$(jq -c ".interfaces[$i]" <<< "$r")
  s0=$(jq ".capture.interfaces[$i].frames" <<< "$before")
  s1=$(jq ".capture.interfaces[$i].frames" <<< "$after")
  [ "$s0" -le "$(jq .counter_start <<< "$w")" ] && [ "$s1" -ge "$(jq .counter_end <<< "$w")" ] ||
    fail "interface $i: status frames $s0 before / $s1 after do not bracket the window $w"
  [ "$(jq ".capture.interfaces[$i].dropped" <<< "$after")" -ge "$(jq .dropped <<< "$w")" ] ||
    fail "interface $i: status counts fewer drops than the reply $w"
done
w0=$(jq -c '.interfaces[0]' <<< "$r")
tx=$(($(jq .bus.counters.tx_frames <<< "$after") - $(jq .bus.counters.tx_frames <<< "$before")))
rx=$(($(jq .bus.counters.rx_frames <<< "$after") - $(jq .bus.counters.rx_frames <<< "$before")))
[ "$tx" -ge "$(jq .tx <<< "$w0")" ] && [ "$rx" -ge "$(jq .rx <<< "$w0")" ] ||
  fail "the cycle port's socket counters grew by tx $tx rx $rx around the capture, less than captured: $w0"
echo "ok: status around the capture: capture points' numbers bracket the window; the cycle port's sockets sent $tx / received $rx frames meanwhile, the window holds $(jq .tx <<< "$w0") / $(jq .rx <<< "$w0")"

# ---- 3 ------------------------------------------------------------------------------------------
"$check" candump "$d/can.log" "$d/candump.json" "$d/replayed.log" || exit $?
exit 0
