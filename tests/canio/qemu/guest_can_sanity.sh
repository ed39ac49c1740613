#!/bin/bash
# Guest script for run-guest.sh: the kernel's CAN stack and the emulated bus work,
# checked with can-utils before any project code is trusted on them.
#  1. can0 and can1 report the configured bit rate, restart-ms and state ERROR-ACTIVE;
#  2. a standard and an extended frame sent on can0 arrive on can1 with their data, and a frame
#     sent on can1 arrives on can0 (two SJA1000 controllers on one emulated bus);
#  3. a frame sent on vcan0 is received on vcan0;
#  4. a receiver's filter shows in /proc/net/can/rcvlist_fil and its error mask in rcvlist_err
#     (where the end-to-end test looks for the daemon's).
set -u
ip=/usr/sbin/ip
tmp=$(mktemp -d)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null; done
  rm -rf "$tmp"
}
trap cleanup EXIT
failed=0
fail() { echo "FAIL: $*"; failed=1; }
pass() { echo "ok: $*"; }

. "$(dirname "$0")/guest_lib.sh"
# A receiver is ready once its socket is in the kernel's receive lists for that device.
receiver_on() { file_has /proc/net/can/rcvlist_all "^ +$1 " || file_has /proc/net/can/rcvlist_fil "^ +$1 "; }

# 1. link parameters
for dev in can0 can1; do
  details=$($ip -details link show "$dev")
  echo "$details" | sed 's/^/  /'
  echo "$details" | grep -q "bitrate $CANIO_BITRATE " &&
    echo "$details" | grep -q "restart-ms $CANIO_RESTART_MS" &&
    echo "$details" | grep -q "state ERROR-ACTIVE" &&
    pass "$dev: bitrate $CANIO_BITRATE, restart-ms $CANIO_RESTART_MS, ERROR-ACTIVE" ||
    fail "$dev: ip -details link show lacks bitrate $CANIO_BITRATE / restart-ms $CANIO_RESTART_MS / ERROR-ACTIVE"
done

# send_and_expect RXDEV TXDEV FRAME EXPECT: candump on RXDEV sees FRAME sent with cansend on TXDEV.
send_and_expect() {
  local rx=$1 tx=$2 frame=$3 expect=$4 out=$tmp/dump.$1.$RANDOM p
  candump -t a -n 1 -T 60000 "$rx" > "$out" 2>&1 &
  p=$!
  pids+=("$p")
  until_true 10 receiver_on "$rx" || { fail "candump on $rx never registered"; return; }
  cansend "$tx" "$frame" || { fail "cansend $tx $frame failed"; return; }
  wait "$p"
  if grep -qE "$expect" "$out"; then
    pass "$tx -> $rx: $(sed 's/^ *//' "$out")"
  else
    fail "$tx -> $rx: $frame not received (candump said: $(cat "$out"))"
  fi
}
# 2. across the emulated bus, both directions, standard and extended identifiers
send_and_expect can1 can0 "123#DEADBEEF01020304" "can1 +123 +\[8\] +DE AD BE EF 01 02 03 04"
send_and_expect can1 can0 "1ABCDE12#C0FFEE" "can1 +1ABCDE12 +\[3\] +C0 FF EE"
send_and_expect can0 can1 "7FF#11" "can0 +7FF +\[1\] +11"
# 3. the virtual CAN device
send_and_expect vcan0 vcan0 "321#A5" "vcan0 +321 +\[1\] +A5"

# 4. a filtered receiver with an error mask shows up in the kernel's lists, and receives
candump -t a -n 1 -T 60000 "can1,181:7FF,#FFFFFFFF" > "$tmp/filtered" 2>&1 &
pids+=($!)
if until_true 20 file_has /proc/net/can/rcvlist_fil "^ +can1 +0*181 +0*7ff "; then
  pass "rcvlist_fil has candump's filter:$(grep -E '^ +can1 ' /proc/net/can/rcvlist_fil | tr -s ' ')"
else
  fail "filter can1 181:7FF not in /proc/net/can/rcvlist_fil: $(cat /proc/net/can/rcvlist_fil)"
fi
if until_true 20 file_has /proc/net/can/rcvlist_err "^ +can1 +[0-9a-f]+ +0*1fffffff "; then
  pass "rcvlist_err has candump's error mask:$(grep -E '^ +can1 ' /proc/net/can/rcvlist_err | tr -s ' ')"
else
  fail "error mask on can1 not in /proc/net/can/rcvlist_err: $(cat /proc/net/can/rcvlist_err)"
fi
cat /proc/net/can/rcvlist_fil /proc/net/can/rcvlist_err | sed 's/^/  /'
cansend can0 "180#02" # not matching the filter
cansend can0 "181#01"
wait "${pids[-1]}"
if file_has "$tmp/filtered" "can1 +181 +\[1\] +01" && ! file_has "$tmp/filtered" " 180 "; then
  pass "filtered receiver got 181#01 and not 180#02"
else
  fail "filtered receiver: expected only 181#01, got: $(cat "$tmp/filtered")"
fi

$ip -s -details link show can0 | sed 's/^/  /'
exit $failed
