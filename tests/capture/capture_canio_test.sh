#!/bin/bash
# ds1928ctl capture on a CAN-I/O run over the cross-process virtual CAN bus: ds1928d (bus: canio)
# against `ds1928-sim canio`, as `make run-canio` runs them.
#
# Checks:
#  1. a 5 s pcapng capture while the daemon cycles: two interfaces (cycle port, SDO port), every
#     frame SocketCAN (LINKTYPE_CAN_SOCKETCAN) decoded by tshark's CAN dissector, none malformed;
#     SYNC (0x080) and the module's objects present, both directions marked;
#  2. counts match exactly per interface: frames in the file = the reply's captured, tx/rx per
#     epb_flags = the reply's, captured + dropped = counter_end - counter_start, ISB likewise;
#  3. --format candump writes can-utils log lines that log2asc (can-utils' own parser) reads;
#     a POWERLINK-only format request on this bus is not needed: candump on POWERLINK is refused
#     in the unit of the service (capture_powerlink_test).
#
# Usage: capture_canio_test.sh BUILD_DIR SOURCE_DIR     (exit 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
here=$src/tests/capture

require_programs "$sim" "$daemon" "$ctl"
skip_unless_tools jq tshark python3

test_init capture_canio
vbus=capcan-$tag
on_cleanup 'rm -f "/dev/shm/ds1928d_capcan_$tag" "/dev/shm/ds1928-vcan.$vbus"'
ctl() { "$ctl" -s "$tmp/ctl.sock" "$@"; }
status() { ctl --json status 2>/dev/null; }

# The shipped run-canio configuration, on this test's own virtual bus, shm and socket.
sed -e "s/virtual_bus: ds1928-sim/virtual_bus: $vbus/" -e '/^shm:/,$d' "$src/config/canio-sim.yaml" >"$tmp/can.yaml"
cat >>"$tmp/can.yaml" <<YAML
shm:
  name: /ds1928d_capcan_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
YAML
grep -q "^cycle:" "$tmp/can.yaml" && sed -i "s/^cycle:/cycle:\n  hold_cpu_dma_latency: false/" "$tmp/can.yaml"
"$daemon" --check-config "$tmp/can.yaml" >"$tmp/check.log" 2>&1 || fail "check-config refused it"

"$sim" canio --virtual "$vbus" --config "$tmp/can.yaml" >"$tmp/sim.log" 2>&1 &
track $!
"$daemon" --config "$tmp/can.yaml" >"$tmp/daemon.log" 2>&1 &
track $!
up=0
for ((i = 0; i < 1200; i++)); do
  [ "$(status | jq -r '.axes[0].state')" = valid ] && { up=1; break; }
  sleep 0.05
done
[ $up = 1 ] || fail "the CAN-I/O axis did not become valid within 60 s"
pass "CAN-I/O node configured, axis valid"

# ---- 1 + 2 ------------------------------------------------------------------------------------
ctl --json capture -w "$tmp/can.pcapng" --duration 5 >"$tmp/reply.json" 2>"$tmp/capture.log" ||
  fail "capture failed: $(cat "$tmp/capture.log")"
r=$(jq -c .capture "$tmp/reply.json")
total=$(tshark -r "$tmp/can.pcapng" 2>"$tmp/tshark.log" | wc -l)
sed -i '/Running as user/d' "$tmp/tshark.log"
[ -s "$tmp/tshark.log" ] && fail "tshark complained: $(cat "$tmp/tshark.log")"
can=$(tshark -r "$tmp/can.pcapng" -Y can 2>/dev/null | wc -l)
bad=$(tshark -r "$tmp/can.pcapng" -Y '_ws.malformed || _ws.expert.severity >= error' 2>/dev/null)
sync=$(tshark -r "$tmp/can.pcapng" -Y 'can.id == 0x080' 2>/dev/null | wc -l)
objects=$(tshark -r "$tmp/can.pcapng" -Y 'can.id == 0x281 || can.id == 0x381 || can.id == 0x301' 2>/dev/null | wc -l)
[ "$total" -gt 1000 ] || fail "only $total frames in 5 s"
[ -z "$bad" ] || fail "malformed or erroneous frames: $(head -5 <<<"$bad")"
[ "$can" = "$total" ] || fail "$can of $total frames decoded as CAN"
[ "$sync" -gt 0 ] && [ "$objects" -gt 0 ] || fail "SYNC $sync, objects $objects"
summary=""
while read -r idx name epbs out inb ifrecv ifdrop; do
  i=$(jq -c ".interfaces[$idx]" <<<"$r")
  window=$(( $(jq .counter_end <<<"$i") - $(jq .counter_start <<<"$i") ))
  [ "$epbs" = "$(jq .captured <<<"$i")" ] || fail "interface $idx: $epbs frames in the file, reply $i"
  [ "$out" = "$(jq .tx <<<"$i")" ] && [ "$inb" = "$(jq .rx <<<"$i")" ] ||
    fail "interface $idx directions: file $out/$inb, reply $i"
  [ $(( epbs + $(jq .dropped <<<"$i") )) = "$window" ] || fail "interface $idx: window $window, reply $i"
  [ "$ifrecv" = "$window" ] && [ "$ifdrop" = "$(jq .dropped <<<"$i")" ] ||
    fail "interface $idx ISB: ifrecv $ifrecv ifdrop $ifdrop, reply $i"
  summary+="$(jq -r .description <<<"$i"): $epbs (tx $out, rx $inb, dropped $ifdrop); "
done < <(python3 "$here/isb_drops.py" "$tmp/can.pcapng" || echo "x")
[ "$(jq '.interfaces | length' <<<"$r")" = 2 ] || fail "expected 2 interfaces: $r"
per_if=$(tshark -r "$tmp/can.pcapng" -T fields -e frame.interface_id 2>/dev/null | sort | uniq -c | tr -s ' ' | tr '\n' ';')
pass "5 s capture: $total CAN frames (SYNC $sync, objects $objects), none malformed; $summary tshark per interface: $per_if"

# ---- 3: candump log --------------------------------------------------------------------------
ctl --json capture --format candump -w "$tmp/can.log.txt" --duration 1 >"$tmp/reply2.json" 2>"$tmp/capture2.log" ||
  fail "candump capture failed: $(cat "$tmp/capture2.log")"
lines=$(wc -l <"$tmp/can.log.txt")
[ "$lines" = "$(jq .capture.frames "$tmp/reply2.json")" ] || fail "candump: $lines lines, reply $(cat "$tmp/reply2.json")"
grep -vEq '^\([0-9]{10}\.[0-9]{6}\) [^ ]+ ([0-9A-F]{3}|[0-9A-F]{8})#([0-9A-F]{2}){0,8}$|#R$' "$tmp/can.log.txt" &&
  fail "candump lines not in can-utils log format: $(grep -vE '#' "$tmp/can.log.txt" | head -3)"
if command -v log2asc >/dev/null; then
  log2asc -I "$tmp/can.log.txt" -O "$tmp/can.asc" "$vbus" >/dev/null 2>&1 || fail "log2asc refused the log"
  asc=$(grep -cE '^ *[0-9]+\.[0-9]+ ' "$tmp/can.asc")
  [ "$asc" = "$lines" ] || fail "log2asc read $asc of $lines frames"
  pass "candump log: $lines lines, all read by can-utils' log2asc ($(head -1 "$tmp/can.log.txt"))"
else
  pass "candump log: $lines lines in can-utils log format (log2asc not installed)"
fi
