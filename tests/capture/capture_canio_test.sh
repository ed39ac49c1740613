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
#  3. --format candump writes can-utils log lines that log2asc (can-utils' own parser) reads.
#  (candump on POWERLINK is refused in the unit of the service: capture_powerlink_test.)
# Checks 1-3 are check_can_capture.sh's, shared with the QEMU guest's capture test over the
# kernel's CAN stack (tests/canio/qemu/guest_canio_capture.sh, which also replays the log with
# canplayer).
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
"$daemon" --no-host-checks --check-config "$tmp/can.yaml" >"$tmp/check.log" 2>&1 || fail "check-config refused it"

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
"$here/check_can_capture.sh" pcapng "$tmp/can.pcapng" "$tmp/reply.json" 1000 >"$tmp/check_pcapng.txt"
rc=$?
cat "$tmp/check_pcapng.txt"
[ $rc = 0 ] || fail "the 5 s pcapng capture"

# ---- 3: candump log --------------------------------------------------------------------------
ctl --json capture --format candump -w "$tmp/can.log.txt" --duration 1 >"$tmp/reply2.json" 2>"$tmp/capture2.log" ||
  fail "candump capture failed: $(cat "$tmp/capture2.log")"
"$here/check_can_capture.sh" candump "$tmp/can.log.txt" "$tmp/reply2.json" >"$tmp/check_candump.txt"
rc=$?
cat "$tmp/check_candump.txt"
[ $rc = 0 ] || fail "the candump log"
