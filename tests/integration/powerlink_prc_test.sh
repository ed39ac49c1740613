#!/bin/bash
# PollResponse Chaining on the wire: the MN (pl_mn_runner: PowerlinkBus on a RawLink) with a mixed
# cycle — nodes 1 and 2 configured `prc: true`, node 3 polled with PReq/PRes — against ds1928-sim
# hosting the three nodes, over a veth pair between two network namespaces.
#  1. all three OPERATIONAL, then held HOLD_SECONDS (default 15) at 1 ms: 0 resets (overruns
#     reported: they measure the machine's load, which make stress raises on purpose);
#  2. the capture (tshark's POWERLINK dissector): SyncRequests and SyncResponses exchanged, one
#     PResMN per SoC in the hold, never a PReq to node 1 or 2, PReqs to node 3, each PRC node's
#     PRes after the PResMN in as many cycles, no malformed frame;
#  3. the simulator's own view: nodes 1 and 2 in PRC mode at their assigned times, node 3 not;
#  4. the daemon's cycle work with a PRC slot allocates nothing;
#  5. ds1928d as the MN: EnDat commands over Flatstream (read-param), the identification and
#     error acknowledgement on the modules behind the chained nodes, whose outputs travel in the
#     PResMN only (the simulator counts the PResMN outputs its modules took).
# Usage: powerlink_prc_test.sh BUILD_DIR SOURCE_DIR   (root; 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
hold=${HOLD_SECONDS:-15}

require_root "network namespaces, veth, raw sockets, SCHED_FIFO"
probe=$build/bench/cycle/host_stall_probe
require_programs "$sim" "$mn" "$probe"
require_tools tshark python3

test_init powerlink_prc
ns_mn=plp_mn_$tag
ns_cn=plp_cn_$tag
netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" plp_mn "$ns_cn" plp_cn

cat >"$tmp/prc.yaml" <<YAML
bus: powerlink
cycle:
  period_us: 1000
powerlink:
  interface: plp_mn
  nodes:
    - {node_id: 1, prc: true}
    - {node_id: 2, prc: true}
    - {node_id: 3}
axes:
  - {name: a1, node: 1, slot: 1}
  - {name: a2, node: 2, slot: 1}
  - {name: a3, node: 3, slot: 1}
YAML

# A sender's own frames do not show on its interface (PACKET_QDISC_BYPASS): the MN's frames are
# captured at the CN's end, the CNs' at the MN's (one clock: one machine).
ip netns exec "$ns_mn" tshark -n -i plp_mn -w "$tmp/mn_end.pcapng" >"$tmp/tshark.log" 2>&1 &
tshark_pid=$!
pids+=($tshark_pid)
ip netns exec "$ns_cn" tshark -n -i plp_cn -w "$tmp/cn_end.pcapng" >"$tmp/tshark_cn.log" 2>&1 &
tshark_cn_pid=$!
pids+=($tshark_cn_pid)
wait_for "$tmp/tshark.log" "Capturing on" 30 || fail "tshark did not start"
wait_for "$tmp/tshark_cn.log" "Capturing on" 30 || fail "tshark at the CN's end did not start"
ip netns exec "$ns_cn" "$sim" powerlink --iface plp_cn --node 1 --count 3 --config "$tmp/prc.yaml" \
    >"$tmp/sim.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
# Each CPU's stops that the machine did not schedule (bench/cycle/host_stall_probe, SCHED_FIFO 99):
# a SoC gap a stopped CPU accounts for is the host's, not the MN's.
"$probe" --out "$tmp/stalls.txt" >"$tmp/probe.log" 2>&1 &
probe_pid=$!
pids+=($probe_pid)
wait_for "$tmp/probe.log" '^probing [0-9]+ CPU' 10 || fail "host_stall_probe never said it measures"
ip netns exec "$ns_mn" "$mn" --iface plp_mn --config "$tmp/prc.yaml" --rt-priority 80 \
    --warmup 1 --duration "$hold" --boot-timeout 30 >"$tmp/mn.log" 2>&1
rc=$?
kill -INT "$probe_pid"
wait "$probe_pid" || fail "host_stall_probe: $(cat "$tmp/probe.log")"
sleep 0.2
kill -INT "$tshark_pid" "$tshark_cn_pid"
wait "$tshark_pid" "$tshark_cn_pid" 2>/dev/null
kill -TERM "$sim_pid"
wait "$sim_pid" 2>/dev/null
grep '^RESULT' "$tmp/mn.log" >"$tmp/result.log" || { cat "$tmp/mn.log"; fail "no RESULT from the MN (exit $rc)"; }
measured=$(field "$tmp/result.log" measured_cycles)
fired=$(field "$tmp/result.log" measured_threshold_fired)
resets=$(field "$tmp/result.log" resets)
overruns=$(field "$tmp/result.log" overruns)
[ "$rc" = 0 ] || fail "MN exit $rc (3: wrong position or stamp, 4: boot timeout): $(cat "$tmp/result.log")"
# The window's grid slots are each run or skipped after an overrun (a host that stops the MN's CPU
# for milliseconds costs slots, counted in `overruns`, not a failure here): together they cover the
# window, less the slots of the last wake-up's lateness (the window ends at the first wake-up past
# its end). A slot neither run nor skipped is a cycle the MN lost.
skipped=$(field "$tmp/result.log" measured_skipped)
late=$(sed -n 's/^WAKE .* max=\([0-9]*\).*/\1/p' "$tmp/mn.log")
[ $(( ${measured:-0} + ${skipped:-0} )) -ge $((hold * 1000 - ${late:-0} / 1000 - 1)) ] ||
  fail "only $measured cycles run and ${skipped:-?} skipped in ${hold}s (expected $((hold * 1000)) slots)"

tshark() { command tshark --disable-protocol opensafety "$@"; }
for end in mn_end cn_end; do
  tshark -r "$tmp/$end.pcapng" -Y epl -T fields -e frame.time_epoch -e epl.mtyp -e epl.src \
      -e epl.dest -e epl.soa.svid -e epl.asnd.svid -e epl.asnd.nmtcommand.cid -e epl.pres.stat \
      -e epl.asnd.ires.state -e epl.asnd.sres.stat -e epl.soa.svtg -e epl.preq.rd 2>/dev/null ||
    fail "tshark could not read $end.pcapng"
done | sort -t$'\t' -k1,1n >"$tmp/frames.txt"
# Resets judged by the wire (both captures cover the MN's whole run, the window of `resets`): each
# NMTResetNode on the wire must be explained by what the wire shows before it — the MN's SoCs
# stopped longer than the simulator's loss-of-SoC limit (5 ms; a CN falls back by the standard's
# rule: a stall of the MN's host, not of the protocol), the node's PRes missing from its cycles
# often enough for the loss-of-PRes counter (168 at 1 ms; a PRC node's PRes counts when it came
# within 220 µs of the PResMN: the MN's PRC slot, the 200 µs PRes timeout after the chain; node 3's
# when it came within its 200 µs PResTimeout of its PReq, less 20 µs for the two captures'
# stamps), or the node reporting a state the MN resets for. A reset the wire does not explain (the MN counting a PRes lost that came) fails.
wire=$(python3 "$src/tests/integration/pl_prc_resets.py" --pres-timeout-us 200 "$tmp/frames.txt" 168 5 220 100 \
  "$tmp/stalls.txt") ||
  fail "could not judge the resets from the capture"
wire_resets=$(sed -n 's/^resets=\([0-9]*\).*/\1/p' <<<"$wire")
unexplained=$(sed -n 's/.* unexplained=\([0-9]*\).*/\1/p' <<<"$wire")
[ "$wire_resets" = "$resets" ] ||
  fail "$resets resets counted by the MN, $wire_resets NMTResetNode on the wire ($wire)"
[ "${unexplained:-1}" = 0 ] || fail "resets the wire does not explain: $wire; $(cat "$tmp/result.log")"
# The simulator's own thread stopped by its host (not counted as loss of SoC: the MN's SoCs were
# not missed on any wire while both ends stood still).
own=$(sed -n 's/^node 1 stats:.* own_stalls=\([0-9]*\) own_stall_max_us=\([0-9]*\).*/\1 stalls, longest \2 us/p' "$tmp/sim.log")
if [ "$resets" != 0 ]; then
  echo "NOTE: $resets resets ($fired loss-of-PRes thresholds while measured), each explained by the wire: $wire; $(grep '^STALLS\|^WAKE' "$tmp/mn.log" | tr '\n' ' ')"
  # The 10-minute hold (REQUIRE_ZERO_RESETS=1) asks for none but those after the host stopped the
  # MN's CPU for longer than a CN's loss-of-SoC limit, measured by the probe.
  host=$(sed -n 's/.* host_stalled=\([0-9]*\).*/\1/p' <<<"$wire")
  [ "${REQUIRE_ZERO_RESETS:-0}" = 0 ] || [ "$resets" = "${host:-x}" ] ||
    fail "$resets resets in the hold, ${host:-?} of them after a stop of the MN's CPU by its host: $wire; $(tail -n 3 "$tmp/probe.log" | tr '\n' ' ')"
fi
pass "mixed PRC + PReq/PRes cycle held $measured cycles at 1 ms ($skipped slots skipped after overruns): $resets resets ($wire), $overruns overruns; $(grep '^LATENCY' "$tmp/mn.log"); the simulator stopped by its host: ${own:-no figures}; the probe: $(tail -n 3 "$tmp/probe.log" | tr '\n' ' ')"
read -r socs pres_mn preq12 preq3 syncreq syncres pres1 pres2 < <(python3 - "$tmp/frames.txt" <<'PY'
import sys
socs = pres_mn = preq12 = preq3 = syncreq = syncres = 0
pres = {1: 0, 2: 0}
rows = [l.rstrip("\n").split("\t") for l in open(sys.argv[1])]
rows = [r + [""] * (12 - len(r)) for r in rows if len(r) >= 3 and r[1]]
# tshark prints some fields in hex (0x06): numbers compared as numbers.
num = lambda v: str(int(v, 0)) if v else ""
rd = [r[11] in ("1", "True", "true") for r in rows]
rows = [[r[0]] + [num(v) for v in r[1:6]] for r in rows]
# The hold: from the first PResMN on and the MN OPERATIONAL (its first PReq with RD=1: every node
# booted, node 3 back from its NMTResetConfiguration), up to the last SoC whose cycle is complete
# (its SoA seen).
first_mn = next((i for i, r in enumerate(rows) if r[1] == "4" and r[2] == "240"), len(rows))
first_rd = next((i for i, r in enumerate(rows) if r[1] == "3" and rd[i]), len(rows))
first = max(first_mn, first_rd)
while first > 0 and rows[first][1] != "1":
    first -= 1  # from that cycle's SoC
last_soa = max((i for i, r in enumerate(rows) if r[1] == "5"), default=-1)
for i, r in enumerate(rows):
    mtyp, src, dst, soa_svid, asnd_svid = r[1], r[2], r[3], r[4], r[5]
    if mtyp == "3" and dst in ("1", "2"):
        preq12 += 1  # anywhere in the capture, boot included
    if mtyp == "5" and soa_svid == "6":
        syncreq += 1
    if mtyp == "6" and asnd_svid == "6":
        syncres += 1
    if i < first or i > last_soa:
        continue
    if mtyp == "1":
        socs += 1
    elif mtyp == "4" and src == "240":
        pres_mn += 1
    elif mtyp == "3" and dst == "3":
        preq3 += 1
    elif mtyp == "4" and src in ("1", "2"):
        pres[int(src)] += 1
print(socs, pres_mn, preq12, preq3, syncreq, syncres, pres[1], pres[2])
PY
)
[ "$preq12" = 0 ] || fail "$preq12 PReq to the PRC nodes 1/2 on the wire"
[ "${syncreq:-0}" -ge 6 ] && [ "${syncres:-0}" -ge 6 ] ||
  fail "SyncRequests $syncreq, SyncResponses $syncres (two PRC nodes need at least 3 each)"
# In the hold every SoC is followed by one PResMN.
# (A cycle with every PRC node being booted again after a reset has no PResMN.)
[ "${socs:-0}" -gt 1000 ] && [ $((pres_mn - socs)) -le 1 ] &&
  { [ "$resets" != 0 ] || [ $((socs - pres_mn)) -le 1 ]; } ||
  fail "$socs SoCs but $pres_mn PResMN from the first PResMN on ($resets resets)"
# (A node being booted again after a reset is out of the isochronous phase for a while.)
[ "$resets" != 0 ] || [ $((preq3 + 1)) -ge "$socs" ] ||
  fail "only $preq3 PReq to node 3 for $socs SoCs"
# Each PResMN is answered by both PRC nodes unless the MN counted the PRes lost (its count covers
# the whole run and all nodes: it bounds the window's losses from above).
lost=$(field "$tmp/result.log" loss_of_pres_events)
[ "$resets" != 0 ] || [ $((pres1 + pres2 + lost + 2)) -ge $((2 * pres_mn)) ] ||
  fail "PRes of node 1: $pres1, node 2: $pres2 for $pres_mn PResMN and $lost counted lost"
for end in mn_end cn_end; do
  tshark -r "$tmp/$end.pcapng" -Y "_ws.malformed || _ws.expert.severity >= 0x00600000" \
      -T fields -e frame.number -e epl.src -e epl.mtyp -e _ws.expert.message 2>/dev/null
done >"$tmp/expert.txt"
[ -s "$tmp/expert.txt" ] && { head "$tmp/expert.txt"; fail "Wireshark finds malformed frames or expert errors"; }
pass "on the wire: $socs SoCs, $pres_mn PResMN, PRes node 1 $pres1 / node 2 $pres2 ($lost PRes counted lost by the MN), $preq3 PReq to node 3, none to 1 and 2; $syncreq SyncRequests, $syncres SyncResponses; Wireshark clean"

stats() { grep "^node $1 stats" "$tmp/sim.log"; }
for n in 1 2; do
  stats $n | grep -q "prc=yes" || fail "node $n not in PRC mode at the end: $(stats $n)"
done
stats 3 | grep -q "prc=no" || fail "node 3 in PRC mode: $(stats 3)"
t2=$(stats 2 | sed -n 's/.*pres_time_first_ns=\([0-9]*\).*/\1/p')
[ "${t2:-0}" -gt 0 ] || fail "node 2 has no PRes time after node 1's: $(stats 2)"
pass "ds1928-sim: nodes 1, 2 in PRC mode (node 2's PRes $t2 ns after the PResMN), node 3 PReq/PRes"

# ---- 4. the daemon's cycle work with a PRC slot allocates nothing ----------------------------
# The whole cycle work (PowerlinkBus with the PResMN and the PRC slot, decoding, shared memory)
# counted on the cycle thread for 3000 cycles once the bus is operational: no heap allocation, no
# mutex.
noalloc=$build/tests/daemon/powerlink_cycle_noalloc
[ -x "$noalloc" ] || fail "$noalloc not built"
ip netns exec "$ns_cn" "$sim" powerlink --iface plp_cn --node 1 --count 3 --config "$tmp/prc.yaml" \
    >"$tmp/sim4.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
ip netns exec "$ns_mn" "$noalloc" "$tmp/prc.yaml" 3000 >"$tmp/noalloc.log" 2>&1
rc=$?
kill -TERM "$sim_pid"
wait "$sim_pid" 2>/dev/null
[ $rc = 0 ] || fail "cycle work with PRC (exit $rc): $(cat "$tmp/noalloc.log")"
pass "cycle work with PRC: $(head -n1 "$tmp/noalloc.log" | sed 's/^counted //'); $(sed -n 2p "$tmp/noalloc.log")"

# ---- 5. ds1928d: EnDat and error acknowledgement behind the chained nodes -------------------
# A chained node gets no PReq: its module's OutputSequence, Tx bytes and AckErrorInfo reach it in
# the PResMN only. A command timeout is timing (a stall of the daemon or the simulator); any other
# failure is not.
daemon=$build/daemon/ds1928d
ctl=$build/tools/ds1928ctl/ds1928ctl
[ -x "$daemon" ] && [ -x "$ctl" ] || fail "ds1928d or ds1928ctl not built"
sock=$tmp/control.sock
cp "$tmp/prc.yaml" "$tmp/daemon.yaml"
printf 'shm:\n  name: /ds1928d_plp_%s\nsocket:\n  path: %s\n' "$tag" "$sock" >>"$tmp/daemon.yaml"
"$daemon" --no-host-checks --check-config "$tmp/daemon.yaml" >"$tmp/check.log" 2>&1 ||
  fail "ds1928d rejects the PRC configuration: $(cat "$tmp/check.log")"
ip netns exec "$ns_cn" "$sim" powerlink --iface plp_cn --node 1 --count 3 --config "$tmp/prc.yaml" \
    >"$tmp/sim5.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
ip netns exec "$ns_mn" "$daemon" -c "$tmp/daemon.yaml" >"$tmp/daemon.log" 2>&1 &
daemon_pid=$!
pids+=($daemon_pid)
ctl_do() { ip netns exec "$ns_mn" "$ctl" -s "$sock" "$@"; }
up=0
for ((i = 0; i < 300 * ${wait_scale:-1}; i++)); do
  ctl_do --json status 2>/dev/null | grep -q '"active":true.*"active":true' &&
    ctl_do status 2>/dev/null | grep -qE "bus: +powerlink, operational" && { up=1; break; }
  sleep 0.1
done
[ $up = 1 ] || fail "ds1928d did not bring the chained nodes to operational: $(ctl_do status 2>&1 | head -n 20)"
ctl_do --json status >"$tmp/status5.json" 2>&1
grep -q '"outputs_offset":9,"outputs_size":9' "$tmp/status5.json" ||
  fail "node 2's outputs not at 9 (9 bytes) in the PResMN: $(grep -o '"prc":{[^}]*}' "$tmp/status5.json" | tr '\n' ' ')"
for axis in 0 1; do
  ok=1
  for ((k = 0; k < 3; k++)); do
    ctl_do endat -a "$axis" read-param 0xA1 13 >"$tmp/endat$axis.log" 2>&1
    ok=$?
    [ $ok = 0 ] && break
    grep -q "error: timeout" "$tmp/endat$axis.log" || break
    echo "note: EnDat read-param on axis $axis timed out, again: $(cat "$tmp/endat$axis.log")"
  done
  [ $ok = 0 ] || fail "EnDat read-param behind chained node $((axis + 1)) failed: $(cat "$tmp/endat$axis.log")"
  ctl_do endat -a "$axis" ident >"$tmp/ident$axis.log" 2>&1 ||
    fail "EnDat ident behind chained node $((axis + 1)) failed: $(cat "$tmp/ident$axis.log")"
  ctl_do endat -a "$axis" ack >"$tmp/eack$axis.log" 2>&1 ||
    fail "EnDat error acknowledgement behind chained node $((axis + 1)) failed: $(cat "$tmp/eack$axis.log")"
  ctl_do ack "$axis" 0x01 >"$tmp/ack$axis.log" 2>&1 ||
    fail "AckErrorInfo behind chained node $((axis + 1)) failed: $(cat "$tmp/ack$axis.log")"
done
pass "behind the chained nodes: $(head -n1 "$tmp/endat0.log"); $(head -n1 "$tmp/endat1.log"); $(head -n1 "$tmp/eack0.log"); $(head -n1 "$tmp/ack1.log"); ident $(head -n1 "$tmp/ident0.log")"
kill -TERM "$daemon_pid" "$sim_pid"
wait "$daemon_pid" "$sim_pid" 2>/dev/null
for n in 1 2; do
  taken=$(sed -n "s/^node $n stats:.* pres_mn_outputs=\([0-9]*\).*/\1/p" "$tmp/sim5.log")
  [ "${taken:-0}" -gt 100 ] || fail "node $n took the outputs of ${taken:-no} PResMN: $(grep "^node $n stats" "$tmp/sim5.log")"
done
pass "ds1928-sim: the chained nodes took their outputs from the PResMN ($(sed -n 's/^node 1 stats:.*\(pres_mn_outputs=[0-9]*\).*/node 1 \1/p' "$tmp/sim5.log"))"
