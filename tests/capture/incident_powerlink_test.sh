#!/bin/bash
# The flight recorder on a POWERLINK run between two network namespaces (veth): ds1928d as MN in
# one, ds1928-sim as the CN in the other; the CN is killed.
#
# Checks:
#  1. `ds1928ctl incident mark TEXT` writes a file after the tail, listed by `ds1928ctl incidents`
#     (and --json) with its frames;
#  2. killing the CN (SIGKILL) makes the MN reset node 1 (loss of PRes threshold): an incident
#     file of node 1 (kind pres_threshold, node_lost or node_reset), readable by tshark
#     with 0 malformed frames, holding the CN's PRes frames from before the event (the CN is
#     dead after it: no PRes can come later) and the MN's frames of the tail; the daemon's log
#     line names the file; status counts the incident and the axis' bus_down incident;
#  3. the daemon keeps cycling.
#
# Usage: incident_powerlink_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
cpu=$(( $(nproc) > 1 ? 1 : 0 ))

require_root "network namespaces, veth, raw sockets"
require_programs "$sim" "$daemon" "$ctl"
skip_unless_tools jq tshark

test_init incident_powerlink
ns_mn=incmn_$tag
ns_cn=inccn_$tag
on_cleanup 'rm -f "/dev/shm/ds1928d_inc_$tag" "/dev/shm/ds1928d_inc_$tag.wait"'
mn() { ip netns exec "$ns_mn" "$@"; }
ctl() { mn "$ctl" -s "$tmp/ctl.sock" "$@"; }
status() { ctl --json status 2>/dev/null; }
tshark() { command tshark --disable-protocol opensafety "$@"; }

cat >"$tmp/inc.yaml" <<YAML
bus: powerlink
cycle:
  period_us: 1000
  cpu: $cpu
  hold_cpu_dma_latency: false
powerlink:
  interface: incmn
  nodes:
    - node_id: 1
      vendor_id: 0x0000001A
axes:
  - name: axis0
    node: 1
    slot: 1
shm:
  name: /ds1928d_inc_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
flight_recorder:
  dir: $tmp/incidents
  before_s: 10
  after_ms: 300
YAML
"$daemon" --no-host-checks --check-config "$tmp/inc.yaml" >"$tmp/check.log" 2>&1 || fail "check-config refused it"

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" incmn "$ns_cn" inccn
ip netns exec "$ns_cn" "$sim" powerlink --iface inccn --node 1 --config "$tmp/inc.yaml" \
    --profile software-cn --cpu "$cpu" >"$tmp/sim.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
ip netns exec "$ns_mn" "$daemon" --config "$tmp/inc.yaml" >"$tmp/daemon.log" 2>&1 &
pids+=($!)

up=0
for ((i = 0; i < 1200; i++)); do
  [ "$(status | jq -r '.axes[0].state')" = valid ] && { up=1; break; }
  sleep 0.05
done
[ $up = 1 ] || fail "the CN did not reach OPERATIONAL with a valid axis within 60 s"
pass "CN operational, axis valid"
sleep 2  # frames in the ring before the events

# ---- 1: a manual mark --------------------------------------------------------------------------
ctl incident mark "before the kill" >"$tmp/mark.log" 2>&1 || fail "incident mark: $(cat "$tmp/mark.log")"
# (On a loaded machine the software CN may have been reset before: those incidents are listed
# too; the checks select by kind, node and time.)
wait_for "$tmp/daemon.log" "incident [0-9]+: manual mark: before the kill; [0-9]+ frames around it in $tmp/incidents/" 10 ||
  fail "no log line for the manual incident"
ctl --json incidents >"$tmp/list1.json" || fail "incidents --json"
manual=$(jq -c '[.incidents[] | select(.kind == "manual")]' "$tmp/list1.json")
[ "$(jq 'length' <<<"$manual")" = 1 ] && [ "$(jq '.[0].frames' <<<"$manual")" -gt 1000 ] ||
  fail "incidents after the mark: $(cat "$tmp/list1.json")"
mark_file=$(jq -r '.[0].file' <<<"$manual")
[ -f "$mark_file" ] || fail "the listed file $mark_file does not exist"
ctl incidents >"$tmp/list1.txt" || fail "incidents (table)"
grep -q "manual" "$tmp/list1.txt" && grep -qF "$mark_file" "$tmp/list1.txt" || fail "table: $(cat "$tmp/list1.txt")"
pass "manual mark: $(jq -c '.[0] | {kind, frames, bytes}' <<<"$manual")"

# ---- 2: the CN is killed -----------------------------------------------------------------------
kill_ns=$(date +%s%N)  # before the kill: every incident it causes is later
kill -KILL "$sim_pid"
wait "$sim_pid" 2>/dev/null
kill_real=$(date +%s.%N)  # after it: no PRes of the CN can be later
wait_for "$tmp/daemon.log" "incident [0-9]+: powerlink node 1: reset by the MN" 20 ||
  fail "no incident for node 1 after the kill"
sleep 1  # the axis' incident and the tail
ctl --json incidents >"$tmp/list2.json" || fail "incidents --json"
# The first incident of node 1 after the kill (a dead CN may be reset again later, after boot
# timeouts: those are incidents of their own).
node_incidents=$(jq -c --argjson t "$kill_ns" '[.incidents[] | select(.node == 1 and .time_ns >= $t)]' "$tmp/list2.json")
[ "$(jq 'length' <<<"$node_incidents")" -ge 1 ] || fail "no node 1 incident after the kill: $(cat "$tmp/list2.json")"
kind=$(jq -r '.[0].kind' <<<"$node_incidents")
case $kind in pres_threshold | node_lost | node_reset) ;; *) fail "node 1 incident of kind $kind" ;; esac
f=$(jq -r '.[0].file' <<<"$node_incidents")
[ -f "$f" ] || fail "node 1's incident file $f is missing"
[ "$(jq 'length' <<<"$node_incidents")" = 1 ] || echo "NOTE: $(jq 'length' <<<"$node_incidents") incidents of node 1 within 1 s of the kill"
grep -qF "$f" "$tmp/daemon.log" || fail "the log does not name $f"
total=$(tshark -r "$f" 2>"$tmp/tshark.log" | wc -l)
sed -i '/Running as user/d' "$tmp/tshark.log"
[ -s "$tmp/tshark.log" ] && fail "tshark complained: $(cat "$tmp/tshark.log")"
bad=$(tshark -r "$f" -Y '_ws.malformed || _ws.expert.severity >= error' 2>/dev/null | wc -l)
epl=$(tshark -r "$f" -Y epl 2>/dev/null | wc -l)
pres=$(tshark -r "$f" -Y 'epl.mtyp == 4 && epl.src == 1' 2>/dev/null | wc -l)
# The last PRes of the CN lies before the kill; the file goes on after it (the tail: SoC, PReq).
last_pres=$(tshark -r "$f" -Y 'epl.mtyp == 4 && epl.src == 1' -T fields -e frame.time_epoch 2>/dev/null | tail -n1)
last=$(tshark -r "$f" -T fields -e frame.time_epoch 2>/dev/null | tail -n1)
[ "$total" -gt 1000 ] || fail "only $total frames in the incident file"
[ "$bad" = 0 ] || fail "$bad malformed or erroneous frames"
[ "$epl" = "$total" ] || fail "$epl of $total frames decoded as POWERLINK"
[ "$pres" -gt 500 ] || fail "only $pres PRes of node 1 (frames before the event)"
awk -v a="$last_pres" -v b="$kill_real" 'BEGIN { exit !(a < b) }' || fail "a PRes after the kill ($last_pres >= $kill_real)"
awk -v a="$last" -v b="$last_pres" 'BEGIN { exit !(a > b + 0.2) }' || fail "no tail after the last PRes ($last vs $last_pres)"
[ "$(jq -r '.[0].frames' <<<"$node_incidents")" = "$total" ] || fail "listing says $(jq -r '.[0].frames' <<<"$node_incidents") frames, file has $total"
s=$(status)
axis_down=$(jq '.flight_recorder.raised.axis_bus_down' <<<"$s")
[ "$axis_down" -ge 1 ] || fail "no axis_bus_down incident: $(jq -c .flight_recorder <<<"$s")"
pass "CN killed: one $kind incident of node 1, $total frames ($pres PRes of node 1 before the event, 0 malformed), tail to $last (last PRes $last_pres); file named in the log; axis_bus_down raised $axis_down"

# ---- 3 ------------------------------------------------------------------------------------------
c0=$(status | jq .cycle.count)
sleep 0.5
[ "$(status | jq .cycle.count)" -gt "$c0" ] || fail "the daemon stopped cycling"
pass "the daemon keeps cycling; $(ls "$tmp/incidents" | wc -l) incident file(s): $(ls "$tmp/incidents" | tr '\n' ' ')"
