#!/bin/bash
# ds1928d as POWERLINK MN on an interface without carrier, and on one that is not a segment of
# its own:
#  1. the veth's peer end is down at start: the daemon does not exit; `status` says
#     waiting_for_link with the interface and the fix, the log says so, and systemd hears READY=1
#     with STATUS= saying the same (a unit must not fail for a cable plugged in later);
#  2. the peer end comes up and a CN (ds1928-sim) answers: the daemon starts cycling, the bus
#     becomes operational and the axis valid, without a restart;
#  3. the interface gets an IPv4 address: start refuses it, naming the address and the key that
#     allows it; `--check-config` in the namespace says the same; with
#     powerlink.allow_shared_interface: true it starts;
#  4. a second MN started on the segment listens (MNWaitNotAct), hears the first one's SoCs and
#     stays NOT_ACTIVE and silent, status another_mn naming the sender; the first runs on;
#  5. another MN's SoCs while running are counted, the sender named, a foreign_mn incident made.
# Usage: powerlink_link_wait_test.sh BUILD_DIR SOURCE_DIR   (root; 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
require_root "network namespaces, veth, raw sockets"
require_programs "$sim" "$daemon" "$ctl"
require_tools jq python3

test_init powerlink_link_wait
ns_mn=plw_mn_$tag
ns_cn=plw_cn_$tag
on_cleanup 'rm -f "/dev/shm/ds1928d_plw_$tag" "/dev/shm/ds1928d_plw_$tag.wait"'
status() { ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json status 2>/dev/null; }

write_yaml() {  # FILE ALLOW_SHARED
  cat >"$1" <<YAML
bus: powerlink
cycle: {period_us: 2000, hold_cpu_dma_latency: false}
powerlink:
  interface: plw_mn
  allow_shared_interface: $2
  nodes: [{node_id: 1}]
axes: [{name: axis0, node: 1, slot: 1}]
shm: {name: /ds1928d_plw_$tag}
socket: {path: $tmp/ctl.sock, privileged_group: ""}
YAML
}
write_yaml "$tmp/plw.yaml" false
write_yaml "$tmp/shared.yaml" true

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" plw_mn "$ns_cn" plw_cn
ip -n "$ns_cn" link set plw_cn down || fail "peer end down"
for ((i = 0; i < 200; i++)); do
  ip -n "$ns_mn" link show plw_mn | grep -q NO-CARRIER && break
  sleep 0.05
done
ip -n "$ns_mn" link show plw_mn | grep -q NO-CARRIER || fail "plw_mn still has carrier"

# sd_notify's datagrams, one file line per message (newlines inside a message as '|').
python3 - "$tmp/notify.sock" "$tmp/notify.txt" <<'PY' &
import socket, sys
s = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
s.bind(sys.argv[1])
with open(sys.argv[2], "a", buffering=1) as out:
    while True:
        out.write(s.recv(4096).decode(errors="replace").replace("\n", "|") + "\n")
PY
track $!
until_true 10 test -S "$tmp/notify.sock" || fail "no notification socket"

# ---- 1. link down at start: waits ------------------------------------------------------------
ip netns exec "$ns_mn" env NOTIFY_SOCKET="$tmp/notify.sock" "$daemon" --config "$tmp/plw.yaml" \
    >"$tmp/daemon.log" 2>&1 &
dpid=$!
track $dpid
until_true 20 bash -c "[ \"\$(ip netns exec $ns_mn $ctl -s $tmp/ctl.sock --json status 2>/dev/null | jq -r .bus.state)\" = waiting_for_link ]" ||
  fail "no waiting_for_link in status: $(status | jq -c .bus)"
s=$(status)
cause=$(jq -r .bus.cause <<<"$s")
grep -q "plw_mn" <<<"$cause" || fail "the cause does not name the interface: $cause"
grep -q "ip link set plw_mn up" <<<"$cause" || fail "the cause does not give the fix: $cause"
wait_for "$tmp/daemon.log" "waiting for the link: link down on 'plw_mn'" 10 || fail "no log line about the link"
wait_for "$tmp/notify.txt" "READY=1\|STATUS=.*waiting_for_link \(link down on 'plw_mn'" 10 ||
  fail "systemd did not hear READY=1 with STATUS= naming the link: $(cat "$tmp/notify.txt")"
sleep 1
kill -0 $dpid 2>/dev/null || fail "the daemon exited while the link was down"
pass "link down at start: daemon waits (waiting_for_link, '$cause'), READY=1 with STATUS="

# ---- 2. the carrier comes: cycling -----------------------------------------------------------
ip -n "$ns_cn" link set plw_cn up || fail "peer end up"
ip netns exec "$ns_cn" "$sim" powerlink --iface plw_cn --node 1 --config "$tmp/plw.yaml" \
    >"$tmp/sim.log" 2>&1 &
track $!
operational() {
  local s
  s=$(status) || return 1
  [ "$(jq -r .bus.state <<<"$s")" = operational ] && [ "$(jq -r '.axes[0].state' <<<"$s")" = valid ]
}
until_true 60 operational || fail "not operational with a valid axis 60 s after the link came: $(status | jq -c '.bus | {state, cause, link_up}')"
status | jq -e '.bus | has("cause") | not' >/dev/null || fail "an operational bus with a cause"
kill -0 $dpid 2>/dev/null || fail "the daemon is gone"
grep -q "waiting_for_link -> " "$tmp/daemon.log" || fail "the log does not say the link came"
pass "carrier up: operational, axis valid, same process"
kill $dpid
wait $dpid
rc=$?
[ $rc = 0 ] || fail "daemon exit $rc after SIGTERM"

# ---- 3. an interface with an address ---------------------------------------------------------
ip -n "$ns_mn" addr add 10.77.0.1/24 dev plw_mn || fail "address"
rc=0
ip netns exec "$ns_mn" "$daemon" --check-config "$tmp/plw.yaml" >"$tmp/check_shared.out" 2>&1 || rc=$?
[ $rc = 2 ] || fail "--check-config of a shared interface: exit $rc: $(cat "$tmp/check_shared.out")"
grep -q "10.77.0.1/24" "$tmp/check_shared.out" || fail "--check-config does not name the address"
rc=0
ip netns exec "$ns_mn" timeout 30 "$daemon" --config "$tmp/plw.yaml" >"$tmp/refused.log" 2>&1 || rc=$?
[ $rc = 1 ] || fail "start on an interface with an address: exit $rc (expected 1)"
grep -q "interface 'plw_mn' looks like a port of an IP network.*it has the address 10.77.0.1/24" "$tmp/refused.log" ||
  fail "the refusal does not name the address"
grep -q "allow_shared_interface: true" "$tmp/refused.log" || fail "the refusal does not name the key"
ip netns exec "$ns_mn" "$daemon" --config "$tmp/shared.yaml" >"$tmp/shared.log" 2>&1 &
dpid=$!
track $dpid
until_true 20 operational || fail "allow_shared_interface: true did not start: $(tail -n 3 "$tmp/shared.log")"
grep -q "is shared (it has the address 10.77.0.1/24)" "$tmp/shared.log" || fail "no warning about the shared interface"
pass "an interface with 10.77.0.1/24: refused with the address, started with allow_shared_interface"

# ---- 4. another MN on the segment at start: NOT_ACTIVE for good ------------------------------
# A second ds1928d at the CN's end listens first (MNWaitNotAct, 1 s by default), hears the running
# MN's SoCs and stays NOT_ACTIVE, sending nothing: the running MN sees no foreign frame.
cat >"$tmp/second.yaml" <<YAML
bus: powerlink
cycle: {period_us: 2000, hold_cpu_dma_latency: false}
powerlink:
  interface: plw_cn
  nodes: [{node_id: 1}]
axes: [{name: axis0, node: 1, slot: 1}]
shm: {name: /ds1928d_plw2_$tag}
socket: {path: $tmp/ctl2.sock, privileged_group: ""}
YAML
on_cleanup 'rm -f "/dev/shm/ds1928d_plw2_$tag" "/dev/shm/ds1928d_plw2_$tag.wait"'
ip netns exec "$ns_cn" "$daemon" --config "$tmp/second.yaml" >"$tmp/second.log" 2>&1 &
second=$!
track $second
status2() { ip netns exec "$ns_cn" "$ctl" -s "$tmp/ctl2.sock" --json status 2>/dev/null; }
until_true 20 bash -c "[ \"\$(ip netns exec $ns_cn $ctl -s $tmp/ctl2.sock --json status 2>/dev/null | jq -r .bus.state)\" = another_mn ]" ||
  fail "the second MN does not report another_mn: $(status2 | jq -c .bus)"
s2=$(status2)
mac_mn=$(ip -n "$ns_mn" link show plw_mn | awk '/link\/ether/ {print $2}')
cause=$(jq -r .bus.cause <<<"$s2")
grep -qE "another Managing Node is active on 'plw_cn' \((SoC|PReq|SoA) from $mac_mn" <<<"$cause" ||
  fail "the cause does not name the interface, the frame and the sender $mac_mn: $cause"
[ "$(jq -r .bus.mn_state <<<"$s2")" = NOT_ACTIVE ] || fail "the second MN is not NOT_ACTIVE: $(jq -c .bus.mn_state <<<"$s2")"
[ "$(jq -r .bus.foreign_mn.at_start <<<"$s2")" = true ] || fail "foreign_mn.at_start: $(jq -c .bus.foreign_mn <<<"$s2")"
wait_for "$tmp/second.log" "another Managing Node is active on 'plw_cn'" 10 || fail "the second MN's log does not say it"
sleep 1
operational || fail "the running MN lost its bus to the second one: $(status | jq -c '.bus | {state, cause}')"
[ "$(status | jq .bus.counters.foreign_mn_frames)" = 0 ] ||
  fail "the running MN heard the silent second one: $(status | jq -c .bus.counters)"
kill $second
wait $second 2>/dev/null
pass "a second MN at start: another_mn ('$cause'), NOT_ACTIVE, silent; the running MN undisturbed"

# ---- 5. another MN's SoC while running: counted, named, an incident --------------------------
ip netns exec "$ns_cn" python3 "$src/tests/integration/pl_send_frames.py" plw_cn soc:3:54 >"$tmp/send.log" 2>&1 ||
  fail "could not send the foreign SoCs: $(cat "$tmp/send.log")"
until_true 10 bash -c "[ \"\$(ip netns exec $ns_mn $ctl -s $tmp/ctl.sock --json status 2>/dev/null | jq .bus.counters.foreign_mn_frames)\" = 3 ]" ||
  fail "3 foreign SoCs sent, the MN counts $(status | jq -c .bus.counters)"
s=$(status)
[ "$(jq -r .bus.foreign_mn.last_source_mac <<<"$s")" = 02:00:00:00:54:54 ] ||
  fail "the sender is not named: $(jq -c .bus.foreign_mn <<<"$s")"
[ "$(jq -r .bus.foreign_mn.at_start <<<"$s")" = false ] || fail "at_start for a frame while running"
until_true 10 bash -c "ip netns exec $ns_mn $ctl -s $tmp/ctl.sock --json incidents 2>/dev/null | jq -e '[.incidents[] | select(.kind == \"foreign_mn\")] | length >= 1' >/dev/null" ||
  fail "no foreign_mn incident: $(ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json incidents 2>&1 | head -c 400)"
operational || fail "the MN stopped on another MN's SoCs"
pass "3 SoCs of another MN while running: counted, sender 02:00:00:00:54:54 named, foreign_mn incident, still operational"
