#!/bin/bash
# A third-party CN configured the standard way, end to end with real frames: ds1928d (the
# daemon, no axes) in one network namespace boots ds1928-sim without modules (a generic CN) in
# another, from the MN's concise DCF (mnobd.cdc, 0x1F22/9 = the CN's objects) — the form
# openCONFIGURATOR writes.
#
# Checks:
#  1. `ds1928d --check-config` accepts the configuration (no axes, CDC file);
#  2. the CN reaches OPERATIONAL; the MN wrote every object of 0x1F22/9 (none refused) and the
#     CN's PRes has the size its written mapping (0x1A00) defines, its PReq the written limit
#     (0x1F98/4); it reported the configuration date and time the MN's lists expect
#     (0x1F26/0x1F27) after the MN's NMTResetConfiguration;
#  3. the raw PRes is published (`ds1928ctl pl pres`), PReq bytes set with `pl preq-set` reach
#     the CN (its PReq payload carries them on the wire);
#  4. the MN sent the CN nothing but NMT, Ident/StatusRequests, the identity read (0x1018/1) and
#     the configuration's SDO writes (no module register access);
#  5. Wireshark decodes every frame of both directions with no malformed packet or expert
#     error/warning.
# Usage: powerlink_generic_cn_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"

require_root "network namespaces, veth, AF_PACKET raw sockets"
require_programs "$sim" "$daemon" "$ctl"
require_tools jq
have_tshark=1
command -v tshark >/dev/null || { have_tshark=0; echo "NOTE: tshark not installed, frame check skipped"; }

test_init powerlink_generic
ns_mn=plg_mn_$tag
ns_cn=plg_cn_$tag
if_mn=plg_mn
if_cn=plg_cn
on_cleanup 'rm -f "/dev/shm/ds1928d_plg_$tag" "/dev/shm/ds1928d_plg_$tag.wait"'

ctlj() { ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json "$@"; }
node9() { ctlj status 2>/dev/null | jq -c '.bus.nodes[] | select(.node == 9)' 2>/dev/null; }

# ---- The concise DCF (node 9's objects: tests/integration/generic_cdc.sh) -------------------
. "$src/tests/integration/generic_cdc.sh"
write_generic_cdc "$tmp" 9

cat >"$tmp/generic.yaml" <<YAML
# A generic CN (no X20DS1928) configured from openCONFIGURATOR's mnobd.cdc.
cycle:
  period_us: 1000
bus: powerlink
powerlink:
  interface: $if_mn
  cdc: mnobd.cdc
  nodes:
    - node_id: 9
      pres_timeout_us: 500
  # Holding a CN through the stalls of a busy 2-core machine is another test's subject; here a
  # reset would only restart the configuration being checked.
  thresholds:
    loss_of_pres: 0
  async_timeout_us: 200
shm:
  name: /ds1928d_plg_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
YAML

"$daemon" --no-host-checks --check-config "$tmp/generic.yaml" >"$tmp/check.log" 2>&1 || fail "check-config refused it"
pass "configuration without axes, from a concise DCF, accepted ($(tail -n1 "$tmp/check.log"))"

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" "$if_mn" "$ns_cn" "$if_cn"
if [ $have_tshark = 1 ]; then
  ip netns exec "$ns_cn" tshark -i "$if_cn" -f "ether proto 0x88ab" -w "$tmp/mn_frames.pcapng" \
      >"$tmp/tshark.log" 2>&1 &
  tshark_pid=$!
  pids+=($!)
  ip netns exec "$ns_mn" tshark -i "$if_mn" -f "ether proto 0x88ab" -w "$tmp/cn_frames.pcapng" \
      >"$tmp/tshark_cn.log" 2>&1 &
  tshark_cn_pid=$!
  pids+=($!)
  wait_for "$tmp/tshark.log" "Capturing on" 30 || fail "tshark did not start"
  wait_for "$tmp/tshark_cn.log" "Capturing on" 30 || fail "tshark (MN end) did not start"
fi

ip netns exec "$ns_cn" "$sim" powerlink --iface "$if_cn" --node 9 --config "$tmp/generic.yaml" \
    >"$tmp/sim.log" 2>&1 &
pids+=($!)
ip netns exec "$ns_mn" "$daemon" --config "$tmp/generic.yaml" >"$tmp/daemon.log" 2>&1 &
pids+=($!)

up=0
for ((i = 0; i < 600; i++)); do
  [ "$(node9 | jq -r .boot)" = operational ] && { up=1; break; }
  sleep 0.05
done
[ $up = 1 ] || fail "node 9 did not reach OPERATIONAL"
grep -q "modules 0\|0 module" "$tmp/sim.log" || true
n=$(node9)
echo "node 9: $(echo "$n" | jq -c '{boot, preq_size, pres_size, configuration}')"
# objects_written counts every boot (a loss-of-PRes reset boots the CN again).
written=$(echo "$n" | jq .configuration.objects_written)
[ "$written" -ge ${#cn_entries[@]} ] && [ $((written % ${#cn_entries[@]})) = 0 ] ||
  fail "not every object of 0x1F22/9 was written ($written)"
[ "$(echo "$n" | jq .configuration.object_failures)" = 0 ] || fail "the CN refused objects"
[ "$(echo "$n" | jq .configuration.configuration_not_verified)" = 0 ] ||
  fail "the CN reported another configuration date/time after the MN's NMTResetConfiguration"
[ "$(echo "$n" | jq .pres_size)" = 10 ] || fail "PRes size is not the mapped 10 bytes"
[ "$(echo "$n" | jq .preq_size)" = 4 ] || fail "PReq size is not the written limit of 4"
[ "$(echo "$n" | jq .pres_size_mismatches)" = 0 ] || fail "the CN's PRes size differs from the configured"
pass "node 9 OPERATIONAL, configured from mnobd.cdc: ${#cn_entries[@]} objects written per boot, none refused, PRes 10 / PReq 4 bytes"

pres=$(ctlj pl pres 9) || fail "pl pres failed"
[ "$(echo "$pres" | jq .size)" = 10 ] || fail "raw PRes of node 9 is not 10 bytes: $pres"
ctlj pl preq-set 9 1 a5c3 >"$tmp/preq.log" 2>&1 || fail "pl preq-set refused: $(cat "$tmp/preq.log")"
pass "raw PRes published (10 bytes), PReq bytes set"
sleep 1  # frames with the new PReq bytes on the wire; more cycles of the hold
n=$(node9)
echo "node 9 after ~1 s more: resets $(echo "$n" | jq .resets), PRes losses $(echo "$n" | jq .loss_of_pres.events)"

if [ $have_tshark = 1 ]; then
  sleep 0.2
  kill -INT "$tshark_pid" "$tshark_cn_pid"
  wait "$tshark_pid" "$tshark_cn_pid" 2>/dev/null
  tshark() { command tshark --disable-protocol opensafety "$@"; }
  # The PReq to node 9 carries the bytes set, 4 bytes payload.
  # (the payload starts at frame byte 24; the dissector shows it as no field of its own)
  preqs=$(tshark -r "$tmp/mn_frames.pcapng" \
      -Y "epl.preq && epl.dest == 9 && epl.preq.size == 4 && frame[24:4] == 00:a5:c3:00" \
      2>/dev/null | wc -l)
  [ "$preqs" -gt 0 ] || fail "no PReq carried the bytes set with pl preq-set"
  # Nothing but NMT, Ident/Status and SDO from the MN; one SDO read (0x1018/1: the vendor id
  # 0x1F85/9 gives), the rest writes (command id 0x01 WriteByIndex) — no module register access.
  sdo_reads=$(tshark -r "$tmp/mn_frames.pcapng" -Y "epl.asnd.sdo.cmd.command.id == 0x02 && epl.src == 240" 2>/dev/null | wc -l)
  # One identity read per configuration run (a reset starts one more; one may be under way).
  runs=$(($(node9 | jq .configuration.objects_written) / ${#cn_entries[@]}))
  [ "$sdo_reads" -ge 1 ] && [ "$sdo_reads" -le $((runs + 1)) ] ||
    fail "the MN read $sdo_reads objects in $runs configuration runs; one identity read per run expected"
  sdo_writes=$(tshark -r "$tmp/mn_frames.pcapng" -Y "epl.asnd.sdo.cmd.command.id == 0x01 && epl.src == 240" 2>/dev/null | wc -l)
  [ "$sdo_writes" -ge ${#cn_entries[@]} ] || fail "only $sdo_writes SDO writes on the wire"
  for cap in mn_frames cn_frames; do
    tshark -r "$tmp/$cap.pcapng" -Y "_ws.malformed || _ws.expert.severity >= 0x00600000" \
        -T fields -e frame.number -e epl.src -e epl.mtyp -e _ws.expert.message >"$tmp/expert_$cap.txt" 2>/dev/null
    [ -s "$tmp/expert_$cap.txt" ] && { head "$tmp/expert_$cap.txt"; fail "Wireshark finds malformed $cap"; }
    undecoded=$(tshark -r "$tmp/$cap.pcapng" -Y "eth.type == 0x88ab && !epl" 2>/dev/null | wc -l)
    [ "$undecoded" = 0 ] || fail "$undecoded frames of $cap not decoded"
  done
  pass "Wireshark decodes both directions cleanly ($sdo_writes SDO writes, $sdo_reads identity read(s), PReq with the set bytes)"
fi
echo "PASS"
