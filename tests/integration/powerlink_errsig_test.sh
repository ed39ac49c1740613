#!/bin/bash
# Error signalling end to end with real frames: ds1928d (no axes) in one network namespace boots
# ds1928-sim (node 9, no modules) in another; then the sim raises error entries during the run
# (SIGRTMIN, the sim's test hook).
#
# Checks:
#  1. the CN reaches OPERATIONAL with the handshake done (`exception.signalling` = ready,
#     `handshakes` ≥ 1, none given up) and no error entry;
#  2. a raised entry reaches `ds1928ctl status` (JSON and text: code 0x1928, vendor, occurred,
#     additional information 1) and the daemon's log (`error entry 0x1928`);
#  3. a second entry arrives exactly once more (entries_total 2, additional information 2);
#  4. tshark reads the StatusResponse with EN and the entry code from the capture.
# Usage: powerlink_errsig_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"

require_root "network namespaces, veth, AF_PACKET raw sockets"
require_programs "$sim" "$daemon" "$ctl"
require_tools jq tshark

test_init powerlink_errsig
ns_mn=ples_mn_$tag
ns_cn=ples_cn_$tag
if_mn=ples_mn
if_cn=ples_cn
on_cleanup 'rm -f "/dev/shm/ds1928d_ples_$tag" "/dev/shm/ds1928d_ples_$tag.wait"'
ctlj() { ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json "$@"; }
node9() { ctlj status 2>/dev/null | jq -c '.bus.nodes[] | select(.node == 9)' 2>/dev/null; }

cat >"$tmp/errsig.yaml" <<YAML
# 10 ms: the CN's loss-of-SoC timeout (5 periods) rides through the stalls of a busy machine,
# which would reset it and empty its queue — the hold is another test's subject.
cycle:
  period_us: 10000
bus: powerlink
powerlink:
  interface: $if_mn
  nodes:
    - node_id: 9
      pres_timeout_us: 2000
  thresholds:
    loss_of_pres: 0
  async_timeout_us: 2000
shm:
  name: /ds1928d_ples_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
YAML

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" "$if_mn" "$ns_cn" "$if_cn"

# The CN's frames are seen at the MN's end (it sends past the qdisc).
ip netns exec "$ns_mn" tshark -i "$if_mn" -f "ether proto 0x88ab" -w "$tmp/cn_frames.pcapng" \
  >"$tmp/tshark.log" 2>&1 &
tshark_pid=$!
pids+=($tshark_pid)
wait_for "$tmp/tshark.log" "Capturing on" 60 || fail "tshark did not start"

ip netns exec "$ns_cn" "$sim" powerlink --iface "$if_cn" --node 9 --modules 0 >"$tmp/sim.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
ip netns exec "$ns_mn" "$daemon" --config "$tmp/errsig.yaml" >"$tmp/daemon.log" 2>&1 &
pids+=($!)

is_ready() { [ "$(node9 | jq -r '"\(.boot) \(.exception.signalling)"')" = "operational ready" ]; }
until_true 60 is_ready || fail "node 9 not OPERATIONAL with the handshake done: $(node9 | jq -c .exception)"
n=$(node9)
[ "$(echo "$n" | jq .exception.handshakes)" -ge 1 ] || fail "no handshake counted"
[ "$(echo "$n" | jq .exception.handshakes_given_up)" = 0 ] || fail "handshake given up"
[ "$(echo "$n" | jq .exception.entries_total)" = 0 ] || fail "entries before any was raised"
resets=$(echo "$n" | jq .resets)
pass "node 9 OPERATIONAL, error signalling ready ($(echo "$n" | jq -c '.exception | {handshakes, new, acknowledged}'))"

kill -RTMIN "$sim_pid" || fail "cannot signal ds1928-sim"
has_entries() { [ "$(node9 | jq .exception.entries_total)" = "$1" ]; }
until_true 20 has_entries 1 || fail "the raised entry did not reach status: $(node9 | jq -c .exception)"
n=$(node9)
e=$(echo "$n" | jq -c '.exception.entries[-1]')
[ "$(echo "$e" | jq .code)" = $((0x1928)) ] || fail "wrong entry: $e"
echo "$e" | jq -r .text | grep -q "^0x1928 (vendor, occurred, emergency) at .* info 01 00 00 00 00 00 00 00$" ||
  fail "entry text: $e"
ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" status >"$tmp/status.txt" 2>&1
grep -q "error signalling ready" "$tmp/status.txt" && grep -q "0x1928 (vendor, occurred" "$tmp/status.txt" ||
  fail "ds1928ctl status does not show it: $(cat "$tmp/status.txt")"
wait_for "$tmp/daemon.log" "powerlink node 9: error entry 0x1928" 10 || fail "the daemon did not log the entry"
pass "entry raised in the sim reached ds1928ctl status and the log: $(echo "$e" | jq -r .text)"

kill -RTMIN "$sim_pid"
until_true 20 has_entries 2 || fail "second entry: $(node9 | jq -c .exception)"
for _ in 1 2 3 4 5 6 7 8 9 10; do
  has_entries 2 || fail "an entry was recorded twice: $(node9 | jq -c .exception)"
  sleep 0.1
done
n=$(node9)
[ "$(echo "$n" | jq -r '.exception.entries[-1].text' | grep -c 'info 02 00')" = 1 ] ||
  fail "the second entry is not the second raise: $(echo "$n" | jq -c .exception.entries)"
[ "$(echo "$n" | jq -r .boot)" = operational ] || fail "node 9 left OPERATIONAL"
pass "second entry recorded exactly once; node 9 OPERATIONAL, resets during the test: $(($(echo "$n" | jq .resets) - resets)) ($(echo "$n" | jq -c '.exception | {signalled, entries_total, acknowledged}'))"

kill "$tshark_pid" 2>/dev/null
wait "$tshark_pid" 2>/dev/null
codes=$(tshark -r "$tmp/cn_frames.pcapng" -Y "epl.asnd.sres.el.entry.code == 0x1928" \
  -T fields -e epl.asnd.sres.en 2>/dev/null | wc -l)
[ "$codes" -ge 2 ] || fail "tshark sees $codes StatusResponses with entry 0x1928"
pass "tshark: $codes StatusResponses carry entry 0x1928"
exit 0
