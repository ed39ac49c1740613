#!/bin/bash
# Guest script for run-guest.sh: ds1928d on can0 against ds1928-sim canio on can1, over the
# kernel's real CAN stack (two SJA1000 controllers on QEMU's emulated bus). Checks:
#  1. the daemon starts on SocketCAN: bus canio operational, transport socketcan, the interface's
#     bit rate and restart-ms as set with ip link;
#  2. the module was configured at start over SDO (status: configured, SDO transfers, the log);
#  3. positions in shared memory: fresh samples valid, moving, stamped with the kernel's receive
#     time (time source rx_timestamp, stamp <= publication, monotonic) — check_positions.py;
#  4. the daemon's receive filters on can0 are exactly its identifiers (/proc/net/can/rcvlist_sff,
#     rcvlist_fil)
#     and its error-frame subscription is in effect (rcvlist_err);
#  5. position objects of wrong length are counted as such and never published; frames on an
#     identifier the daemon does not use never reach it (kernel filters);
#  6. `ds1928ctl endat ident` and `endat read-param` are answered (EnDat over Flatstream on CAN);
#  7. the same checks fail when the daemon has a wrong identifier: with object 2 on an identifier
#     nobody sends, no sample is ever fresh (check_positions.py fails; --expect-no-fresh holds).
# Nothing about timing is asserted: the guest's CPU is emulated.
#
# Usage: guest_canio_e2e.sh BUILD_DIR SOURCE_DIR [--config FILE]
#   --config runs checks 1-6 with FILE instead of canio_guest.yaml (e.g. a wrong identifier, to see
#   the test fail); the simulator always uses canio_guest.yaml.
set -u
build=${1:?build dir}
src=${2:?source dir}
shift 2
here=$src/tests/canio/qemu
sim_config=$here/canio_guest.yaml
daemon_config=$sim_config
while [ $# -gt 0 ]; do
  case "$1" in
    --config) daemon_config=$(realpath "${2:?file}"); shift 2 ;;
    *) echo "usage: guest_canio_e2e.sh BUILD_DIR SOURCE_DIR [--config FILE]"; exit 2 ;;
  esac
done
. "$here/guest_lib.sh"
daemon=$build/daemon/ds1928d
sim=$build/tools/ds1928-sim/ds1928-sim
ctl=$build/tools/ds1928ctl/ds1928ctl
for bin in "$daemon" "$sim" "$ctl"; do
  [ -x "$bin" ] || { echo "FAIL: $bin not built"; exit 1; }
done

tmp=$(mktemp -d /tmp/canio_e2e.XXXXXX)
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
  # The work directory outlives the guest: the logs stay there for the host to show.
  [ -n "${CANIO_WORK:-}" ] && cp "$tmp"/*.log "$tmp"/*.txt "$CANIO_WORK/" 2> /dev/null
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
uptime_ns() {
  local up
  read -r up _ < /proc/uptime
  echo $((${up/./} * 10000000))
}

# ---- the simulated node on can1 -----------------------------------------------------------------
# Faults: every 50th position object 7 bytes long (the daemon must count it and publish no sample
# for that cycle), and after every SYNC a frame on 0x285, an identifier the daemon does not use
# (its kernel filters must keep it out).
"$sim" canio --iface can1 --node 1 --config "$sim_config" --wrong-length-every 50 \
  --unexpected-id 0x285 > "$tmp/sim.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
# Ready once its receive filters are in the kernel's lists for can1 (exact 11-bit filters are kept
# in rcvlist_sff, masked ones in rcvlist_fil).
sim_filters() { file_has /proc/net/can/rcvlist_sff "^ +can1 " || file_has /proc/net/can/rcvlist_fil "^ +can1 "; }
until_true 60 sim_filters ||
  fail "ds1928-sim canio registered no receive filter on can1 within 60 s"
kill -0 $sim_pid 2> /dev/null || fail "ds1928-sim exited"
pass "ds1928-sim canio on can1: $(head -n1 "$tmp/sim.log")"

# start_daemon NAME CONFIG: ds1928d on its own shm and socket; sets shm, sock, daemon_pid, t_start.
start_daemon() {
  local name=$1 config=$2
  shm=/ds1928d_cq_${name}_$tag
  sock=$tmp/$name.sock
  cp "$config" "$tmp/$name.yaml"
  printf 'shm:\n  name: %s\nsocket:\n  path: %s\n' "$shm" "$sock" >> "$tmp/$name.yaml"
  "$daemon" --no-host-checks --check-config "$tmp/$name.yaml" > "$tmp/$name-check.log" 2>&1 ||
    fail "ds1928d rejects $config: $(tail -n 5 "$tmp/$name-check.log")"
  t_start=$(uptime_ns)
  "$daemon" -c "$tmp/$name.yaml" > "$tmp/$name.log" 2>&1 &
  daemon_pid=$!
  pids+=($daemon_pid)
}
# status NAME: the daemon's status as shell variables (status_vars.py, one coprocess for the whole
# test), the JSON in NAME-status.txt.
coproc STATUS_VARS { exec python3 "$here/status_vars.py" --serve; }
pids+=($STATUS_VARS_PID)
status() {
  local line vars=""
  "$ctl" --json --timeout 20000 -s "$sock" status > "$tmp/$1-status.txt" 2>> "$tmp/ctl.log" || return 1
  echo "$tmp/$1-status.txt 0" >&"${STATUS_VARS[1]}"
  while read -r -t 60 line <&"${STATUS_VARS[0]}"; do
    [ "$line" = "#end" ] && break
    vars+="$line"$'\n'
  done
  [ "$line" = "#end" ] || fail "status_vars.py does not answer"
  eval "$vars"
}
# The bus cycles as soon as the controller can send; the axis is usable once its node is
# configured (per-axis availability).
operational() { status "$1" && [ "$bus_state" = operational ] && [ "$configured" = 1 ]; }
stop_daemon() {
  kill -TERM "$daemon_pid" 2> /dev/null
  wait "$daemon_pid" 2> /dev/null
}
# positions FILE COUNT: COUNT publications of axis 0 (bounded).
positions() {
  timeout 90 "$ctl" --json --timeout 60000 --shm "$shm" position --axis 0 --follow --count "$2" \
    > "$1" 2>> "$tmp/ctl.log"
}

# ---- 1. the daemon on can0 ----------------------------------------------------------------------
start_daemon good "$daemon_config"
until_true 60 operational good || {
  kill -0 "$daemon_pid" 2> /dev/null || fail "ds1928d exited: $(tail -n 5 "$tmp/good.log")"
  fail "ds1928d not operational within 60 s (bus state '${bus_state:-?}')"
}
[ "$bus_kind" = canio ] && [ "$transport" = socketcan ] && [ "$interface" = can0 ] ||
  fail "status says bus $bus_kind over $transport on $interface, expected canio over socketcan on can0"
[ "$bitrate" = "$CANIO_BITRATE" ] && [ "$restart_ms" = "$CANIO_RESTART_MS" ] ||
  fail "status says bitrate $bitrate restart-ms $restart_ms, ip link set $CANIO_BITRATE / $CANIO_RESTART_MS"
pass "ds1928d: bus canio operational over socketcan on can0, $bitrate bit/s, restart-ms $restart_ms, controller $can_state"

# ---- 2. the module configured at start ----------------------------------------------------------
[ "$configured" = 1 ] || fail "node $node not configured (last error: $last_error)"
[ "${n_sdo_transfers:-0}" -gt 0 ] || fail "node configured without any SDO transfer"
[ "${n_sdo_errors:-0}" = 0 ] || fail "$n_sdo_errors SDO errors (last error: $last_error)"
pass "module configured at start by SDO: ${n_sdo_transfers} transfers, ${n_configurations:-?} configuration(s); log: $(grep -m1 -E "axis 0: EnDat" "$tmp/good.log" | cut -d' ' -f4-)"

# ---- 3. positions with receive-time stamps ------------------------------------------------------
# 300 publications for 30 fresh samples: in a QEMU guest under TSan on a loaded host, 26 in 100
# were fresh (the node answers fewer SYNCs), so the window is wide; 30 fresh still shows flow.
positions "$tmp/positions.txt" 300 || fail "ds1928ctl position --follow failed: $(tail -n 3 "$tmp/ctl.log")"
python3 "$here/check_positions.py" --min-fresh 30 --since-ns "$((t_start - 20000000))" \
  < "$tmp/positions.txt" > "$tmp/check.txt"
rc=$?
cat "$tmp/check.txt"
[ $rc = 0 ] || fail "positions in shared memory"

# ---- 4. the daemon's filters and error subscription on can0 -------------------------------------
# Nothing else has a socket on can0: every can0 entry is the daemon's.
status good || fail "status"
sdo_rx=$((0x580 + node))
ids=()
# Exact 11-bit filters live in rcvlist_sff, masked ones in rcvlist_fil: both count.
mapfile -t fil < <(cat /proc/net/can/rcvlist_sff /proc/net/can/rcvlist_fil)
for line in "${fil[@]}"; do
  [[ $line =~ ^\ +can0\ +([0-9a-f]+)\ +([0-9a-f]+)\  ]] || continue
  id=$((16#${BASH_REMATCH[1]}))
  mask=${BASH_REMATCH[2]}
  [[ $mask == *7ff ]] || fail "can0 filter for id $(printf 0x%X $id) has mask $mask, not an exact 11-bit match"
  ids+=("$id")
done
# The node port also takes the node's boot-up / heartbeat (0x700 + node) and EMCY (0x080 + node).
want=("$in_id0" "$in_id1" "$sdo_rx" "$((0x700 + node))" "$((0x80 + node))")
for w in "${want[@]}"; do
  [[ " ${ids[*]} " == *" $w "* ]] || fail "no can0 filter for id $(printf 0x%X "$w"): $(printf '%s\n' "${fil[@]}")"
done
for id in "${ids[@]}"; do
  [[ " ${want[*]} " == *" $id "* ]] || fail "can0 filter for id $(printf 0x%X "$id"), which the daemon does not use"
done
printf '  %s\n' "${fil[@]}" | grep -E "can0|device" | head -n 8
pass "can0 receive filters are exactly the daemon's identifiers: $(printf '0x%X ' "${want[@]}")(inputs, SDO response, error control, EMCY)"
file_has /proc/net/can/rcvlist_err "^ +can0 +[0-9a-f]+ +[0-9a-f]*[1-9a-f][0-9a-f]* " ||
  fail "no error-frame subscription on can0: $(cat /proc/net/can/rcvlist_err)"
pass "error-frame subscription on can0: $(grep -E '^ +can0 ' /proc/net/can/rcvlist_err | tr -s ' ' | head -n 2 | tr '\n' ';')"

# ---- 5. frames of wrong length and with foreign identifiers -------------------------------------
[ "${n_wrong_length:-0}" -gt 0 ] ||
  fail "the simulator's 7-byte position objects were not counted as wrong length (wrong_length ${n_wrong_length:-?})"
[ "${c_unexpected_ids:-x}" = 0 ] ||
  fail "frames on 0x285 reached the daemon (unexpected_ids ${c_unexpected_ids:-?}): its filters let them through"
pass "7-byte position objects counted (wrong_length $n_wrong_length) and never published (check 3); 0x285 after every SYNC kept out by the kernel filters (unexpected_ids 0; can0 received $(< /sys/class/net/can0/statistics/rx_packets) frames, the daemon's sockets ${c_rx_frames:-?})"

# ---- 6. EnDat over Flatstream on CAN ------------------------------------------------------------
"$ctl" --timeout 60000 -s "$sock" endat ident > "$tmp/ident.txt" 2>&1 ||
  fail "ds1928ctl endat ident: $(cat "$tmp/ident.txt")"
[ -s "$tmp/ident.txt" ] || fail "ds1928ctl endat ident printed nothing"
pass "endat ident: $(tr -s ' \n' ' ' < "$tmp/ident.txt" | cut -c1-160)"
"$ctl" --timeout 60000 -s "$sock" endat read-param 0xA1 13 > "$tmp/param.txt" 2>&1 ||
  fail "ds1928ctl endat read-param 0xA1 13: $(cat "$tmp/param.txt")"
pass "endat read-param 0xA1 13: $(tr -s ' \n' ' ' < "$tmp/param.txt" | cut -c1-160)"
stop_daemon

# ---- 7. a wrong identifier makes these checks fail ----------------------------------------------
# Object 2 on 0x3F1, which the simulator never sends: only half samples arrive.
awk '
  /^ *identifiers:/ { print "  identifiers: explicit"; print "  axes:";
                      print "    - input_ids: [" in0 ", 0x3F1]"; print "      output_id: " out; next }
  { print }' in0="$in_id0" out="$out_id" "$daemon_config" > "$tmp/wrong_id.yaml"
start_daemon wrong "$tmp/wrong_id.yaml"
configured_wrong() { status wrong && [ "$configured" = 1 ] && [ "${n_half_samples:-0}" -gt 0 ]; }
until_true 60 configured_wrong || fail "daemon with a wrong identifier: not configured / no half samples (state '${bus_state:-?}', $(tail -n 3 "$tmp/wrong.log"))"
positions "$tmp/positions_wrong.txt" 50 || fail "ds1928ctl position --follow (wrong identifier)"
python3 "$here/check_positions.py" --expect-no-fresh --min-fresh 1 < "$tmp/positions_wrong.txt" \
  > "$tmp/check_wrong.txt"
rc=$?
cat "$tmp/check_wrong.txt"
[ $rc = 0 ] || fail "fresh positions with a wrong identifier"
status wrong
pass "wrong identifier 0x3F1: no fresh sample, the position check fails; status: samples ${n_samples:-?}, half samples ${n_half_samples:-?}, silent $silent"
stop_daemon

# ---- 8. object 2 late in 30 % of the cycles: no torn sample ----------------------------------------
# The node sends object 2 of SYNC n 10.2 ms late — after SYNC n+1 (period 10 ms), before its answers
# to it, which wait behind it (FIFO) — and logs what it sent for every SYNC. Every fresh sample
# must carry a position and a PosCycle the node sent together (check_positions.py --answer-log).
kill "$sim_pid" 2> /dev/null
wait "$sim_pid" 2> /dev/null
"$sim" canio --iface can1 --node 1 --config "$sim_config" --late-object2 0.3 \
  --late-object2-us 10200 --answer-log "$tmp/answers.txt" --seed 17 > "$tmp/sim_late.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
until_true 60 sim_filters || fail "ds1928-sim canio (late object 2) registered no receive filter"
start_daemon late "$daemon_config"
late_fresh() { status late && [ "$configured" = 1 ] && [ "${n_samples:-0}" -gt 20 ]; }
until_true 120 late_fresh || fail "daemon against a node with late objects 2: no samples (state '${bus_state:-?}', $(tail -n 3 "$tmp/late.log"))"
positions "$tmp/positions_late.txt" 300 || fail "ds1928ctl position --follow (late object 2)"
python3 "$here/check_positions.py" --min-fresh 20 --since-ns "$((t_start - 20000000))" \
  --answer-log "$tmp/answers.txt" < "$tmp/positions_late.txt" > "$tmp/check_late.txt"
rc=$?
cat "$tmp/check_late.txt"
[ $rc = 0 ] || fail "torn or wrong samples with late objects 2"
status late
pass "object 2 late in 30 % of the cycles: 0 torn; status: samples ${n_samples:-?}, half ${n_half_samples:-?}, unpaired ${n_unpaired:-?}, late frames ${n_late_frames:-?}"
stop_daemon
exit 0
