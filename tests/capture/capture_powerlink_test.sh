#!/bin/bash
# ds1928ctl capture on a POWERLINK run between two network namespaces (veth): ds1928d as MN in
# one, ds1928-sim as the CN in the other.
#
# Checks:
#  1. a 5 s pcapng capture while the daemon cycles: tshark reads every frame, all are POWERLINK
#     (EtherType 0x88AB decoded by the epl dissector), none malformed or with an expert error;
#     both directions marked (epb_flags);
#  2. the counts match exactly: frames in the file per direction = the reply's tx/rx, captured +
#     dropped = counter_end - counter_start (the capture point's counters, also in `status`),
#     and the file's interface statistics (isb_ifrecv, isb_ifdrop) say the same;
#  3. a second capture while one runs is refused (capture_running, naming the running one);
#  4. --count N writes exactly N frames; a client that goes away (pipe closed) ends the capture
#     and the daemon keeps cycling with no capture running; capture-stop ends one early with a
#     complete file; a reader that is not privileged is refused;
#  5. the allocation proof of the cycle over POWERLINK with a capture running (the daemon
#     stopped first: one MN on the link).
#
# Usage: capture_powerlink_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
here=$src/tests/capture
cpu=$(( $(nproc) > 1 ? 1 : 0 ))

require_root "network namespaces, veth, raw sockets"
require_programs "$sim" "$daemon" "$ctl"
skip_unless_tools jq tshark python3

test_init capture_powerlink
ns_mn=capmn_$tag
ns_cn=capcn_$tag
on_cleanup 'rm -f "/dev/shm/ds1928d_cap_$tag" "/dev/shm/ds1928d_cap_$tag.wait"'
mn() { ip netns exec "$ns_mn" "$@"; }
ctl() { mn "$ctl" -s "$tmp/ctl.sock" "$@"; }
status() { ctl --json status 2>/dev/null; }

cat >"$tmp/cap.yaml" <<YAML
bus: powerlink
cycle:
  period_us: 1000
  cpu: $cpu
powerlink:
  interface: capmn
  nodes:
    - node_id: 1
      vendor_id: 0x0000001A
axes:
  - name: axis0
    node: 1
    slot: 1
shm:
  name: /ds1928d_cap_$tag
socket:
  path: $tmp/ctl.sock
  mode: "0666"                  # anyone may connect: the privilege check is the capture's own
  privileged_group: ""
capture:
  max_duration_s: 60
YAML
"$daemon" --no-host-checks --check-config "$tmp/cap.yaml" >"$tmp/check.log" 2>&1 || fail "check-config refused it"

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" capmn "$ns_cn" capcn
ip netns exec "$ns_cn" "$sim" powerlink --iface capcn --node 1 --config "$tmp/cap.yaml" \
    --profile software-cn --cpu "$cpu" >"$tmp/sim.log" 2>&1 &
pids+=($!)
# Started directly, not through mn(): $! must be the daemon (ip netns exec execs it), not a
# subshell whose end would leave the daemon running.
ip netns exec "$ns_mn" "$daemon" --config "$tmp/cap.yaml" >"$tmp/daemon.log" 2>&1 &
daemon_pid=$!
pids+=($daemon_pid)

up=0
for ((i = 0; i < 1200; i++)); do
  [ "$(status | jq -r '.axes[0].state')" = valid ] && { up=1; break; }
  sleep 0.05
done
[ $up = 1 ] || fail "the CN did not reach OPERATIONAL with a valid axis within 60 s"
pass "CN operational, axis valid"

# ---- 1 + 2: five seconds, decoded and counted ------------------------------------------------
s0=$(status)
c0=$(jq '.cycle.count' <<<"$s0")
ctl --json capture -w "$tmp/pl.pcapng" --duration 5 >"$tmp/reply.json" 2>"$tmp/capture.log" ||
  fail "capture failed: $(cat "$tmp/capture.log")"
s1=$(status)
r=$(jq -c '.capture' "$tmp/reply.json")
[ "$(jq -r .reason <<<"$r")" = duration ] || fail "capture ended for another reason: $r"
[ "$(jq -r .running <<<"$(jq -c .capture <<<"$s1")")" = false ] || fail "capture still running"
i0=$(jq -c '.interfaces[0]' <<<"$r")
# Wireshark tries its openSAFETY heuristic on every PReq/PRes payload; on process data that is not
# openSAFETY it can throw ("Malformed Packet: openSAFETY", depending on the position bytes), so
# that dissector is switched off for reading.
tshark() { command tshark --disable-protocol opensafety "$@"; }
total=$(tshark -r "$tmp/pl.pcapng" 2>"$tmp/tshark.log" | wc -l)
sed -i '/Running as user/d' "$tmp/tshark.log"
[ -s "$tmp/tshark.log" ] && fail "tshark complained: $(cat "$tmp/tshark.log")"
epl=$(tshark -r "$tmp/pl.pcapng" -Y epl 2>/dev/null | wc -l)
bad=$(tshark -r "$tmp/pl.pcapng" -Y '_ws.malformed || _ws.expert.severity >= error' 2>/dev/null)
# The expression must be one tshark accepts: a filter with an unknown field fails loudly.
tshark -r "$tmp/pl.pcapng" -Y '_ws.malformed || _ws.expert.severity >= error' -c 1 >/dev/null 2>&1 ||
  fail "tshark refuses the malformed-packet filter"
tx_file=$(tshark -r "$tmp/pl.pcapng" -Y 'frame.packet_flags_direction == 2' 2>/dev/null | wc -l)
rx_file=$(tshark -r "$tmp/pl.pcapng" -Y 'frame.packet_flags_direction == 1' 2>/dev/null | wc -l)
kinds=$(tshark -r "$tmp/pl.pcapng" -T fields -e epl.mtyp 2>/dev/null | sort | uniq -c | awk '{printf "%s×%s ", $2, $1}')
read -r _ _ epbs out inb ifrecv ifdrop < <(python3 "$here/isb_drops.py" "$tmp/pl.pcapng") ||
  fail "pcapng structure"
captured=$(jq .captured <<<"$i0")
window=$(( $(jq .counter_end <<<"$i0") - $(jq .counter_start <<<"$i0") ))
dropped=$(jq .dropped <<<"$i0")
[ "$total" -gt 1000 ] || fail "only $total frames in 5 s"
[ -z "$bad" ] || fail "malformed or erroneous frames: $(head -5 <<<"$bad")"
[ "$epl" = "$total" ] || fail "$epl of $total frames decoded as POWERLINK"
[ "$total" = "$captured" ] || fail "file has $total frames, the reply says $captured captured"
[ $((captured + dropped)) = "$window" ] || fail "captured $captured + dropped $dropped != window $window"
[ "$tx_file" = "$(jq .tx <<<"$i0")" ] && [ "$rx_file" = "$(jq .rx <<<"$i0")" ] ||
  fail "directions: file tx $tx_file rx $rx_file, reply $i0"
[ "$tx_file" -gt 0 ] && [ "$rx_file" -gt 0 ] || fail "one direction missing: tx $tx_file rx $rx_file"
[ "$epbs" = "$total" ] && [ "$out" = "$tx_file" ] && [ "$inb" = "$rx_file" ] || fail "EPB count/flags: $epbs $out $inb"
[ "$ifrecv" = "$window" ] && [ "$ifdrop" = "$dropped" ] || fail "ISB: ifrecv $ifrecv ifdrop $ifdrop, window $window dropped $dropped"
f0=$(jq '.capture.interfaces[0].frames' <<<"$s0")
f1=$(jq '.capture.interfaces[0].frames' <<<"$s1")
[ "$f0" -le "$(jq .counter_start <<<"$i0")" ] && [ "$(jq .counter_end <<<"$i0")" -le "$f1" ] ||
  fail "window $(jq -c '[.counter_start,.counter_end]' <<<"$i0") outside status $f0..$f1"
cycles=$(( $(jq '.cycle.count' <<<"$s1") - c0 ))
pass "5 s capture: $total frames (tx $tx_file, rx $rx_file; $kinds) all decoded as POWERLINK, none malformed; window $window = captured $captured + dropped $dropped; ISB ifrecv $ifrecv ifdrop $ifdrop; daemon cycled $cycles times meanwhile"

# ---- 3: one capture at a time ----------------------------------------------------------------
ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" capture -w "$tmp/long.pcapng" --duration 30 \
    >"$tmp/long.log" 2>&1 &
long_pid=$!
pids+=($long_pid)
for ((i = 0; i < 200; i++)); do
  [ "$(status | jq -r .capture.running)" = true ] && break
  sleep 0.05
done
second=$(ctl capture -w "$tmp/second.pcapng" --duration 1 2>&1)
rc=$?
[ $rc = 1 ] && grep -q "capture_running" <<<"$second" && grep -q "pid" <<<"$second" ||
  fail "a second capture was not refused clearly (rc $rc): $second"
pass "second capture refused: $second"

# capture-stop ends the running one early; its file is complete (statistics at the end).
ctl capture-stop >"$tmp/stop.log" 2>&1 || fail "capture-stop: $(cat "$tmp/stop.log")"
wait "$long_pid" || fail "the stopped capture's client failed: $(cat "$tmp/long.log")"
grep -q "capture ended (stopped)" "$tmp/long.log" || fail "not ended by capture-stop: $(cat "$tmp/long.log")"
read -r _ _ epbs _ _ ifrecv ifdrop < <(python3 "$here/isb_drops.py" "$tmp/long.pcapng") ||
  fail "stopped capture's file"
[ "$ifrecv" != - ] && [ "$epbs" -gt 0 ] || fail "stopped capture lacks its statistics"
pass "capture-stop: $(head -1 "$tmp/long.log") (ISB ifrecv $ifrecv)"

# ---- 4: --count, a client that goes away, permission -----------------------------------------
ctl capture -w "$tmp/count.pcapng" --count 100 >"$tmp/count.log" 2>&1 || fail "count capture: $(cat "$tmp/count.log")"
n=$(tshark -r "$tmp/count.pcapng" 2>/dev/null | wc -l)
[ "$n" = 100 ] || fail "--count 100 wrote $n frames"
read -r _ _ _ _ _ ifrecv ifdrop < <(python3 "$here/isb_drops.py" "$tmp/count.pcapng")
[ $((ifrecv - ifdrop)) = 100 ] || fail "--count 100: ISB ifrecv $ifrecv ifdrop $ifdrop"
pass "--count 100: 100 frames, ISB ifrecv $ifrecv"

c_before=$(status | jq .cycle.count)
ctl capture -w - --duration 20 2>"$tmp/pipe.log" | head -c 3000 >/dev/null
gone=0
for ((i = 0; i < 200; i++)); do
  [ "$(status | jq -r .capture.running)" = false ] && { gone=1; break; }
  sleep 0.05
done
[ $gone = 1 ] || fail "the capture of a client that went away is still running"
grep -q "client gone" "$tmp/daemon.log" || fail "the daemon did not log the end of the capture"
[ "$(status | jq .cycle.count)" -gt "$c_before" ] || fail "the daemon stopped cycling"
pass "a reader that closes its pipe ends the capture; the daemon keeps cycling"

chmod 0711 "$tmp"
denied=$(mn setpriv --reuid=65534 --regid=65534 --clear-groups "$ctl" -s "$tmp/ctl.sock" capture \
    -w /dev/null --duration 1 2>&1)
rc=$?
[ $rc = 1 ] && grep -q "permission_denied" <<<"$denied" ||
  fail "an unprivileged client was not refused (rc $rc): $denied"
pass "unprivileged client refused"

# ---- 5: allocation proof with a capture running ----------------------------------------------
noalloc=$build/tests/daemon/powerlink_cycle_noalloc
if [ -x "$noalloc" ]; then
  kill "$daemon_pid"
  wait "$daemon_pid" 2>/dev/null
  rc=0
  mn "$noalloc" "$tmp/cap.yaml" 3000 capture >"$tmp/noalloc.log" 2>&1 || rc=$?
  [ $rc = 0 ] || fail "cycle work over POWERLINK with a capture (exit $rc): $(cat "$tmp/noalloc.log")"
  pass "allocation proof with capture and flight recorder on: $(head -n1 "$tmp/noalloc.log" | sed 's/^counted //'); $(grep 'capture on' "$tmp/noalloc.log"); $(grep 'flight recorder on' "$tmp/noalloc.log")"
else
  echo "NOTE: powerlink_cycle_noalloc not built: allocation proof with capture skipped"
fi
