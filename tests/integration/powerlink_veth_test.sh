#!/bin/bash
# POWERLINK end to end with real frames: two network namespaces joined by a veth pair, the
# simulated Controlled Node (ds1928-sim) in one, the Managing Node (PowerlinkBus on a raw socket,
# driven by pl_mn_runner) in the other, tshark capturing on the CN's end.
#
# Checks:
#  1. the CN reaches OPERATIONAL and the MN reports all CNs operational;
#  2. the module was configured by SDO (EnDatMode read back over SDO = configured value, the
#     encoder delivers moving positions — with EnDat left disabled it would deliver zeros);
#  3. positions arrive with NetTime stamps mapped to the cycle's time, none wrong;
#  4. a CN power cycle is detected (loss of PRes → reset) and the CN is booted again; a CN asking
#     for its own reset (NMTRequest) is reset and booted again;
#  5. with 5 % random PRes loss no wrong position is published (losses really happened);
#  6. the daemon's cycle work over POWERLINK allocates nothing and takes no mutex;
#  7. every frame type the MN sent (SoC, PReq, SoA incl. NMTRequestInvite, ASnd NMTCommand, ASnd
#     SDO) and every one the CN sent (PRes, IdentResponse, StatusResponse, NMTRequest, SDO) is
#     decoded by Wireshark's POWERLINK dissector with no malformed packet and no expert
#     error/warning.
# Namespaces, processes and files are cleaned up on every exit path.
#
# Built to run in CI next to other load on a 2-core machine that stalls for milliseconds now and
# then: deadlines (process start, boot, re-boot) are generous and counted from the event they wait
# for, time stamps are checked against the real instants around them (not the nominal cycle), and
# a sample taken through the control socket is retried; what must hold on every sample — no
# wrong position, no stamp outside its cycle, SDO read-back, frame decoding — stays strict.
#
# Usage: powerlink_veth_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
config=$src/tests/integration/powerlink_veth.yaml

require_root "network namespaces, veth, AF_PACKET raw sockets"
require_programs "$sim" "$mn"
have_tshark=1
command -v tshark >/dev/null || { have_tshark=0; echo "NOTE: tshark not installed, frame check skipped"; }

test_init powerlink_veth
ns_mn=plt_mn_$tag
ns_cn=plt_cn_$tag
if_mn=plt_mn
if_cn=plt_cn
# Every bound on a wait is multiplied by this (default 3): the bounds stop a hung test, and a
# loaded 2-core machine or a sanitizer build is several times slower than a quiet one.
wait_scale=${DS1928_WAIT_SCALE:-3}

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" "$if_mn" "$ns_cn" "$if_cn"

if [ $have_tshark = 1 ]; then
  # Capture each side's frames on the peer end: with PACKET_QDISC_BYPASS an interface does not
  # see the frames its own raw socket sends. capture.pcapng: the MN's frames, seen by the CN's
  # end; capture_cn.pcapng: the CN's frames, seen by the MN's end.
  ip netns exec "$ns_cn" tshark -i "$if_cn" -f "ether proto 0x88ab" -w "$tmp/capture.pcapng" \
      >"$tmp/tshark.log" 2>&1 &
  pids+=($!)
  tshark_pid=$!
  ip netns exec "$ns_mn" tshark -i "$if_mn" -f "ether proto 0x88ab" -w "$tmp/capture_cn.pcapng" \
      >"$tmp/tshark_cn.log" 2>&1 &
  pids+=($!)
  tshark_cn_pid=$!
  wait_for "$tmp/tshark.log" "Capturing on" 30 || fail "tshark did not start"
  wait_for "$tmp/tshark_cn.log" "Capturing on" 30 || fail "tshark (MN end) did not start"
fi

# ---- Phase 1: boot, SDO configuration, positions, power cycle -------------------------------
ip netns exec "$ns_cn" "$sim" powerlink --iface "$if_cn" --node 1 --config "$config" \
    --power-off-ms 300 >"$tmp/sim1.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
ip netns exec "$ns_mn" "$mn" --iface "$if_mn" --config "$config" --warmup 0 \
    --boot-timeout 30 >"$tmp/mn1.log" 2>&1 &
mn_pid=$!
pids+=($mn_pid)

wait_for "$tmp/mn1.log" "EVENT .* all-operational" 30 || fail "CN did not reach OPERATIONAL"
wait_for "$tmp/sim1.log" "node 1: READY_TO_OPERATE -> OPERATIONAL" 10 ||
  fail "simulator did not report OPERATIONAL"
pass "CN booted to OPERATIONAL ($(grep -m1 'all-operational' "$tmp/mn1.log"))"
wait_for "$tmp/mn1.log" "sdo-readback .* ok" 10 || fail "EnDatMode read back over SDO does not match"
pass "module configured by SDO ($(grep -m1 -o 'sdo-readback.*' "$tmp/mn1.log"))"

sleep 2  # positions flow
# A stall of either side can cost a loss-of-PRes reset before the power cycle (by design at
# threshold 15), so the power cycle's events are counted from here, not from the start. The CN
# must be operational again first.
mn_up() { [ "$(grep -cE "EVENT .* all-operational" "$tmp/mn1.log")" -gt \
            "$(grep -cE "EVENT .* not-all-operational" "$tmp/mn1.log")" ]; }
# Once seen up, it counts: checking again could meet the next stall's reset (seen under stress-ng).
mn_up_wait() { for ((i = 0; i < 600 * wait_scale; i++)); do mn_up && return 0; sleep 0.05; done; return 1; }
mn_up_wait || fail "CN not operational before the power cycle"
up_before=$(grep -cE "EVENT .* all-operational" "$tmp/mn1.log")
down_before=$(grep -cE "EVENT .* not-all-operational" "$tmp/mn1.log")
sim_up_before=$(grep -c "READY_TO_OPERATE -> OPERATIONAL" "$tmp/sim1.log")
kill -USR1 "$sim_pid"  # power cycle: the node goes silent for 300 ms, then boots from scratch
wait_for "$tmp/sim1.log" "power cycle" 10 || fail "simulator did not power-cycle"
wait_for "$tmp/mn1.log" "EVENT .* not-all-operational" 10 $((down_before + 1)) ||
  fail "MN did not notice the power cycle"
wait_for "$tmp/mn1.log" "EVENT .* all-operational" 30 $((up_before + 1)) ||
  fail "CN not booted again after power cycle"
wait_for "$tmp/sim1.log" "READY_TO_OPERATE -> OPERATIONAL" 10 $((sim_up_before + 1)) ||
  fail "simulator not OPERATIONAL again"
pass "power cycle detected and CN re-booted"
# The CN asks for its own reset (NMTRequest after an NMTRequestInvite): the MN resets it, names
# the reason, and boots it again.
mn_up_wait || fail "CN not operational before its NMTRequest"
up_before=$(grep -cE "EVENT .* all-operational" "$tmp/mn1.log")
# A reset for loss of PRes (a stall of this machine beyond the threshold's 20 ms ride-through)
# clears the CN's queued request: then, and only then, the CN asks once more, and the test says so.
loss_resets() { grep -cE 'boot=reset .*loss of PRes' "$tmp/mn1.log"; }
loss_before=$(loss_resets)
kill -USR2 "$sim_pid"
wait_for "$tmp/sim1.log" "NMTRequest: reset of own node queued" 10 || fail "simulator did not queue the NMTRequest"
if ! wait_for "$tmp/mn1.log" 'boot=reset .*last_error="reset requested by the node \(NMTRequest\)"' 10; then
  [ "$(loss_resets)" -gt "$loss_before" ] || fail "MN did not reset the CN on its NMTRequest"
  echo "note: the CN was reset for loss of PRes (stall) before its NMTRequest was served; it asks again"
  mn_up_wait || fail "CN not operational again after the loss-of-PRes reset"
  up_before=$(grep -cE "EVENT .* all-operational" "$tmp/mn1.log")
  kill -USR2 "$sim_pid"
  wait_for "$tmp/mn1.log" 'boot=reset .*last_error="reset requested by the node \(NMTRequest\)"' 10 ||
    fail "MN did not reset the CN on its NMTRequest"
fi
wait_for "$tmp/mn1.log" "EVENT .* all-operational" 30 $((up_before + 1)) ||
  fail "CN not booted again after its NMTRequest"
pass "NMTRequest for the CN's own reset served: reset, re-booted"
sleep 1
kill -TERM "$mn_pid"
wait "$mn_pid"
rc=$?
[ $rc = 0 ] || fail "MN runner exit status $rc (3 = wrong position or bad NetTime stamp)"
grep -q '^RESULT' "$tmp/mn1.log" || fail "MN runner printed no result"
[ "$(field "$tmp/mn1.log" wrong_positions)" = 0 ] || fail "wrong positions published"
[ "$(field "$tmp/mn1.log" bad_stamps)" = 0 ] || fail "positions without valid NetTime stamp"
[ "$(field "$tmp/mn1.log" moving)" -gt 1000 ] || fail "no (moving) positions arrived"
[ "$(field "$tmp/mn1.log" boots)" -ge 2 ] || fail "CN booted fewer than 2 times"
[ "$(field "$tmp/mn1.log" resets)" -ge 1 ] || fail "MN sent no NMTResetNode"
pass "positions with NetTime stamps: $(grep -o 'fresh=[0-9]* moving=[0-9]* wrong_positions=[0-9]* bad_stamps=[0-9]*' "$tmp/mn1.log")"
kill -TERM "$sim_pid"
wait "$sim_pid" 2>/dev/null

if [ $have_tshark = 1 ]; then
  sleep 0.5
  kill -INT "$tshark_pid" "$tshark_cn_pid"
  wait "$tshark_pid" "$tshark_cn_pid" 2>/dev/null
fi

# ---- Phase 2: 5 % random PRes loss -------------------------------------------------------------
# The default loss-of-PRes threshold (168 at 1 ms) lets random single losses pass; at the
# standard's 15, two losses within two cycles (p ≈ 0.5 % per cycle at 5 % loss) would reset the CN.
ip netns exec "$ns_cn" "$sim" powerlink --iface "$if_cn" --node 1 --config "$config" \
    --drop-pres 0.05 --seed 7 >"$tmp/sim2.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
ip netns exec "$ns_mn" "$mn" --iface "$if_mn" --config "$config" --warmup 0.5 --duration 6 \
    --boot-timeout 20 >"$tmp/mn2.log" 2>&1
rc=$?
[ $rc = 0 ] || fail "MN runner with 5 % PRes loss: exit status $rc"
[ "$(field "$tmp/mn2.log" wrong_positions)" = 0 ] || fail "wrong positions with PRes loss"
[ "$(field "$tmp/mn2.log" bad_stamps)" = 0 ] || fail "bad NetTime stamps with PRes loss"
losses=$(field "$tmp/mn2.log" measured_loss_events)
[ "${losses:-0}" -gt 100 ] || fail "expected about 5 % PRes losses, saw ${losses:-0}"
pass "5 % PRes loss: $losses losses in $(field "$tmp/mn2.log" measured_cycles) cycles, $(grep -o 'fresh=[0-9]* moving=[0-9]* wrong_positions=[0-9]*' "$tmp/mn2.log")"
kill -TERM "$sim_pid"
wait "$sim_pid" 2>/dev/null

# ---- Phase 3: the daemon as Managing Node ------------------------------------------------------
# ds1928d with the same configuration (own shared memory and socket), checked through ds1928ctl:
# bus operational, positions in shared memory with NetTime stamps, a power cycle survived.
if [ -x "$daemon" ] && [ -x "$ctl" ]; then
  shm_name=/ds1928d_plt_$tag
  sock=$tmp/control.sock
  cp "$config" "$tmp/daemon.yaml"
  printf 'shm:\n  name: %s\nsocket:\n  path: %s\n' "$shm_name" "$sock" >>"$tmp/daemon.yaml"
  "$daemon" --no-host-checks --check-config "$tmp/daemon.yaml" >"$tmp/check.log" 2>&1 || fail "daemon rejects the test configuration"
  ip netns exec "$ns_cn" "$sim" powerlink --iface "$if_cn" --node 1 --config "$config" \
      --power-off-ms 300 >"$tmp/sim3.log" 2>&1 &
  sim_pid=$!
  pids+=($sim_pid)
  ip netns exec "$ns_mn" "$daemon" -c "$tmp/daemon.yaml" >"$tmp/daemon.log" 2>&1 &
  daemon_pid=$!
  pids+=($daemon_pid)
  ctl_status() { ip netns exec "$ns_mn" "$ctl" -s "$sock" "$@" status >"$tmp/status.txt" 2>&1; }
  up=0
  for ((i = 0; i < 150 * wait_scale; i++)); do
    ctl_status && grep -qE "bus: +powerlink, operational" "$tmp/status.txt" && { up=1; break; }
    sleep 0.1
  done
  cp "$tmp/status.txt" "$tmp/status.log" 2>/dev/null
  [ $up = 1 ] || fail "ds1928d did not bring the POWERLINK bus to operational"
  pass "ds1928d: $(grep -E 'bus:' "$tmp/status.txt" | tr -s ' ')"
  pos() { ip netns exec "$ns_mn" "$ctl" --json --shm "$shm_name" position --axis 0 2>>"$tmp/ctl.log"; }
  num() { echo "$1" | sed -n "s/.*\"$2\":\([-0-9]*\).*/\1/p"; }
  # A stall of this machine longer than two cycles (the CN simulator or the daemon not scheduled)
  # makes the MN reset the CN, as POWERLINK prescribes at the loss-of-PRes threshold; the axis is
  # then bus_down until the CN is booted again (and stale for a single lost PRes). Such a gap is
  # accepted when it closes within 10 s (times the wait scale) and, for bus_down, the daemon's log names the reset with
  # its reason. What a sample says when valid must always hold.
  gaps_down=0
  gaps_stale=0
  sample=
  valid_sample() {
    for ((w = 0; w < 100 * wait_scale; w++)); do
      sample=$(pos)
      echo "$sample" >>"$tmp/position.log"
      case $sample in
        *'"state":"valid"'*) return 0 ;;
        *'"state":"bus_down"'*) gaps_down=$((gaps_down + 1)) ;;
        *'"state":"stale"'*) gaps_stale=$((gaps_stale + 1)) ;;
        *) fail "axis 0 neither valid nor in a gap the bus explains: $sample" ;;
      esac
      sleep 0.1
    done
    fail "axis 0 not valid in shared memory for $((10 * wait_scale)) s: $sample"
  }
  # Every valid sample must be NetTime-stamped and never stamped after its publication; its age
  # at publication is timing (a stall of the cycle thread between receiving and publishing ages
  # it), so one sample of five within 10 ms suffices.
  valid_sample
  p1=$sample
  fresh_ok=0
  for ((k = 0; k < 5; k++)); do
    sleep 0.3
    valid_sample
    p2=$sample
    echo "$p2" | grep -q '"time_source":"nettime"' || fail "position without NetTime stamp: $p2"
    age_us=$(( ($(num "$p2" publish_ns) - $(num "$p2" pos_time_ns)) / 1000 ))
    [ $age_us -ge -1000 ] || fail "NetTime stamp $age_us us after its publication"
    [ $age_us -le 10000 ] && { fresh_ok=1; break; }
    echo "note: NetTime stamp $age_us us before publication (stall?), sampling again"
  done
  [ $fresh_ok = 1 ] || fail "NetTime stamp $age_us us before publication in 5 samples"
  [ "$(num "$p2" position_raw)" != "$(num "$p1" position_raw)" ] || fail "position does not move"
  pass "shared memory: axis 0 valid, NetTime-stamped ($age_us us before publication), moving"
  if [ $gaps_down -gt 0 ] || [ $gaps_stale -gt 0 ]; then
    echo "note: $gaps_down bus_down and $gaps_stale stale samples while waiting for valid ones"
  fi
  if [ $gaps_down -gt 0 ]; then
    grep -q "powerlink node 1: reset by the MN (" "$tmp/daemon.log" ||
      fail "axis 0 was bus_down but the daemon's log names no reset of node 1"
    pass "each bus_down gap explained in the daemon's log: $(grep -m1 "reset by the MN" "$tmp/daemon.log" | sed 's/^.* warning *//')"
  fi
  ip netns exec "$ns_mn" "$ctl" --json -s "$sock" status >"$tmp/status.json" 2>/dev/null
  b0=$(sed -n 's/.*"boots":\([0-9]*\).*/\1/p' "$tmp/status.json")
  kill -USR1 "$sim_pid"
  rebooted=0
  for ((i = 0; i < 150 * wait_scale; i++)); do
    ip netns exec "$ns_mn" "$ctl" --json -s "$sock" status >"$tmp/status.json" 2>/dev/null
    b=$(sed -n 's/.*"boots":\([0-9]*\).*/\1/p' "$tmp/status.json")
    [ "${b:-0}" -gt "${b0:-0}" ] && grep -q '"boot":"operational"' "$tmp/status.json" && { rebooted=1; break; }
    sleep 0.1
  done
  [ $rebooted = 1 ] || fail "ds1928d did not boot the power-cycled CN again"
  pass "ds1928d re-booted the power-cycled CN (boots $b0 -> $b)"
  grep -qE "powerlink node 1: reset by the MN \((loss of PRes threshold reached|node not operational);" \
      "$tmp/daemon.log" || fail "the daemon's log does not name the reset of the power-cycled CN"
  grep -qE "bus powerlink: operational -> booting" "$tmp/daemon.log" ||
    fail "the daemon's log does not show the bus leaving operational"
  # EnDat over Flatstream, when the daemon offers it.
  # A command timeout is timing (a stall of the daemon or the simulator); any other failure is not.
  endat_rc=1
  for ((k = 0; k < 3; k++)); do
    ip netns exec "$ns_mn" "$ctl" -s "$sock" endat read-param 0xA1 13 >"$tmp/endat.log" 2>&1
    endat_rc=$?
    [ $endat_rc = 0 ] && break
    grep -q "error: timeout" "$tmp/endat.log" || break
    echo "note: EnDat read-param timed out, again: $(cat "$tmp/endat.log")"
  done
  if [ $endat_rc = 0 ]; then
    pass "EnDat read-param over Flatstream: $(head -n1 "$tmp/endat.log")"
  elif grep -q "unknown command" "$tmp/endat.log"; then
    echo "NOTE: this ds1928d has no endat-read-param command yet; EnDat check skipped"
  else
    fail "EnDat read-param over Flatstream failed: $(cat "$tmp/endat.log")"
  fi
  # The CN asks for its own reset: the daemon's MN serves it and the journal names the reason.
  # As in phase 1: only a logged loss-of-PRes reset in between lets the CN ask a second time.
  daemon_loss_resets() { grep -c "powerlink node 1: reset by the MN (loss of PRes threshold reached" "$tmp/daemon.log"; }
  requested=0
  for attempt in 1 2; do
    loss_before=$(daemon_loss_resets)
    kill -USR2 "$sim_pid"
    for ((i = 0; i < 150 * wait_scale; i++)); do
      grep -q "powerlink node 1: reset by the MN (reset requested by the node (NMTRequest);" \
          "$tmp/daemon.log" && { requested=1; break; }
      sleep 0.1
    done
    [ $requested = 1 ] && break
    [ "$(daemon_loss_resets)" -gt "$loss_before" ] || break
    echo "note: ds1928d reset the CN for loss of PRes (stall) before serving its NMTRequest; it asks again"
    for ((i = 0; i < 150 * wait_scale; i++)); do
      ip netns exec "$ns_mn" "$ctl" --json -s "$sock" status 2>/dev/null | grep -q '"boot":"operational"' && break
      sleep 0.1
    done
  done
  [ $requested = 1 ] || fail "ds1928d did not reset the CN on its NMTRequest (or did not log it)"
  pass "ds1928d served the CN's NMTRequest: $(grep -m1 'NMTRequest);' "$tmp/daemon.log" | sed 's/^.*warning *//')"
  kill -TERM "$daemon_pid" "$sim_pid"
  wait "$daemon_pid" "$sim_pid" 2>/dev/null
else
  echo "NOTE: ds1928d or ds1928ctl not built: daemon phase skipped"
fi

# ---- Phase 4: the daemon's cycle work over POWERLINK allocates nothing -----------------------
# The whole cycle work (PowerlinkBus on the raw socket with SDO register reads, decoding, the
# Flatstream tunnel with EnDat traffic, shared memory) counted on the cycle thread: no heap
# allocation, no mutex, no page fault, for 3000 cycles once the bus is operational. Another MN's
# SoC arrives every 20 ms from the MN's first SoA on (from the CN's side, past the CN's own
# socket; before, the MN would rightly refuse to start beside another MN): the MN's
# handling of it (counted, named, a foreign_mn incident) is part of the counted cycle work.
noalloc=$build/tests/daemon/powerlink_cycle_noalloc
if [ -x "$noalloc" ]; then
  ip netns exec "$ns_cn" "$sim" powerlink --iface "$if_cn" --node 1 --config "$config" \
      >"$tmp/sim4.log" 2>&1 &
  sim_pid=$!
  pids+=($sim_pid)
  ip netns exec "$ns_cn" python3 "$src/tests/integration/pl_send_frames.py" "$if_cn" --bypass \
      --after-soa-from 240 --timeout 120 \
      --every 20 soc:0:54 >"$tmp/foreign4.log" 2>&1 &
  foreign_pid=$!
  pids+=($foreign_pid)
  ip netns exec "$ns_mn" "$noalloc" "$config" 3000 foreign >"$tmp/noalloc.log" 2>&1
  rc=$?
  kill -TERM "$sim_pid" "$foreign_pid"
  wait "$sim_pid" "$foreign_pid" 2>/dev/null
  [ $rc = 0 ] || fail "cycle work over POWERLINK (exit $rc): $(cat "$tmp/noalloc.log") $(cat "$tmp/foreign4.log")"
  pass "cycle work over POWERLINK: $(head -n1 "$tmp/noalloc.log" | sed 's/^counted //'); $(sed -n 2p "$tmp/noalloc.log"); $(grep '^page faults' "$tmp/noalloc.log"); $(grep '^another MN' "$tmp/noalloc.log")"
else
  echo "NOTE: powerlink_cycle_noalloc not built: allocation check over POWERLINK skipped"
fi

# ---- Wireshark's verdict on the MN's frames --------------------------------------------------
if [ $have_tshark = 1 ]; then
  # Wireshark tries its openSAFETY heuristic on every PReq/PRes payload; on process data that is
  # not openSAFETY it can throw ("Malformed Packet: openSAFETY", depending on the position bytes).
  # The payload here is X20DS1928 process data, so that dissector is switched off.
  tshark() { command tshark --disable-protocol opensafety "$@"; }
  cap=$tmp/capture.pcapng
  [ -s "$cap" ] || fail "empty capture"
  tshark -r "$cap" -Y "epl.src == 240" -T fields -e epl.mtyp -e epl.asnd.svid -e epl.soa.svid \
      >"$tmp/mn_frames.txt" 2>"$tmp/tshark_read.log" || fail "tshark could not read the capture"
  total=$(wc -l <"$tmp/mn_frames.txt")
  soc=$(awk -F'\t' '$1 == 1' "$tmp/mn_frames.txt" | wc -l)
  preq=$(awk -F'\t' '$1 == 3' "$tmp/mn_frames.txt" | wc -l)
  soa=$(awk -F'\t' '$1 == 5' "$tmp/mn_frames.txt" | wc -l)
  nmt=$(awk -F'\t' '$1 == 6 && $2 == 4' "$tmp/mn_frames.txt" | wc -l)
  sdo=$(awk -F'\t' '$1 == 6 && $2 == 5' "$tmp/mn_frames.txt" | wc -l)
  ident_req=$(awk -F'\t' '$1 == 5 && $3 == 1' "$tmp/mn_frames.txt" | wc -l)
  status_req=$(awk -F'\t' '$1 == 5 && $3 == 2' "$tmp/mn_frames.txt" | wc -l)
  echo "MN frames decoded: $total (SoC $soc, PReq $preq, SoA $soa [IdentRequest $ident_req, StatusRequest $status_req], NMTCommand $nmt, SDO $sdo)"
  nmt_invite=$(awk -F'\t' '$1 == 5 && $3 == 3' "$tmp/mn_frames.txt" | wc -l)
  for n in soc preq soa nmt sdo ident_req status_req nmt_invite; do
    [ "${!n}" -gt 0 ] || fail "no $n frame from the MN was decoded as such"
  done
  # Every frame of a capture: no malformed packet, no expert error or warning, none undecoded.
  wireshark_clean() {  # CAPTURE WHOSE
    local out=$tmp/expert_$2.txt
    tshark -r "$1" -Y "_ws.malformed || _ws.expert.severity >= 0x00600000" \
        -T fields -e frame.number -e epl.src -e epl.mtyp -e _ws.expert.message \
        >"$out" 2>>"$tmp/tshark_read.log"
    if [ -s "$out" ]; then
      head -n 20 "$out"
      fail "Wireshark reports malformed $2 frames or expert errors/warnings ($(wc -l <"$out") frames)"
    fi
    local undecoded
    undecoded=$(tshark -r "$1" -Y "eth.type == 0x88ab && !epl" 2>/dev/null | wc -l)
    [ "$undecoded" = 0 ] || fail "$undecoded $2 POWERLINK frames not decoded by the epl dissector"
  }
  wireshark_clean "$cap" MN
  pass "Wireshark decodes every MN frame type with no malformed packet or expert error"

  # The simulated CN's frames (the peer the MN must understand): PRes, IdentResponse,
  # StatusResponse, SDO and the NMTRequest, all decoded without error.
  cap_cn=$tmp/capture_cn.pcapng
  [ -s "$cap_cn" ] || fail "empty capture on the MN's end"
  tshark -r "$cap_cn" -Y "epl.src == 1" -T fields -e epl.mtyp -e epl.asnd.svid \
      >"$tmp/cn_frames.txt" 2>>"$tmp/tshark_read.log" || fail "tshark could not read the CN capture"
  cn_pres=$(awk -F'\t' '$1 == 4' "$tmp/cn_frames.txt" | wc -l)
  cn_ident=$(awk -F'\t' '$1 == 6 && $2 == 1' "$tmp/cn_frames.txt" | wc -l)
  cn_status=$(awk -F'\t' '$1 == 6 && $2 == 2' "$tmp/cn_frames.txt" | wc -l)
  cn_nmt_request=$(awk -F'\t' '$1 == 6 && $2 == 3' "$tmp/cn_frames.txt" | wc -l)
  cn_sdo=$(awk -F'\t' '$1 == 6 && $2 == 5' "$tmp/cn_frames.txt" | wc -l)
  echo "CN frames decoded: $(wc -l <"$tmp/cn_frames.txt") (PRes $cn_pres, IdentResponse $cn_ident, StatusResponse $cn_status, NMTRequest $cn_nmt_request, SDO $cn_sdo)"
  for n in cn_pres cn_ident cn_status cn_nmt_request cn_sdo; do
    [ "${!n}" -gt 0 ] || fail "no $n frame from the CN was decoded as such"
  done
  wireshark_clean "$cap_cn" CN
  pass "Wireshark decodes every CN frame type, the NMTRequest included, with no malformed packet or expert error"
fi
echo "PASS"
