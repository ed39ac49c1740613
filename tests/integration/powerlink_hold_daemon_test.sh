#!/bin/bash
# ds1928d itself holds two CNs whose PRes comes from software, under the documented defaults: a
# bus controller with one X20DS1928 (node 1) and, beside it, a generic CN without modules
# configured from the MN's concise DCF (node 9, mnobd.cdc) — and still detects the generic CN
# when it is really gone, without touching its neighbour.
#
# Two network namespaces joined by a veth pair; in the CN namespace two ds1928-sim processes with
# the software-CN profile (responder blocking in the kernel, SCHED_FIFO 50, log-normal PRes delay
# with a long tail) on the same CPU as the daemon's cycle thread (SCHED_FIFO 80).
#  1. HOLD_SECONDS (default 100 = 10^5 cycles at 1 ms): both CNs OPERATIONAL throughout, zero
#     resets, no reset line in the journal, the axis valid with NetTime stamps and no format
#     violation, at least 95 % of the cycles run;
#  2. the generic CN is killed: node 9 is reset for "loss of PRes threshold reached"; node 1
#     keeps running with zero resets.
# Run time ≈ HOLD_SECONDS + 20 s.
# Usage: powerlink_hold_daemon_test.sh BUILD_DIR SOURCE_DIR   (root; 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
hold=${HOLD_SECONDS:-100}
cpu=$(( $(nproc) > 1 ? 1 : 0 ))

require_root "network namespaces, veth, raw sockets, SCHED_FIFO"
require_programs "$sim" "$daemon" "$ctl"
require_tools jq

test_init powerlink_hold_daemon
ns_mn=plhd_mn_$tag
ns_cn=plhd_cn_$tag
on_cleanup 'rm -f "/dev/shm/ds1928d_plhd_$tag" "/dev/shm/ds1928d_plhd_$tag.wait"'
status() { ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json status 2>/dev/null; }
node() { jq -c ".bus.nodes[] | select(.node == $1)" <<<"$2"; }

. "$src/tests/integration/generic_cdc.sh"
write_generic_cdc "$tmp" 9

# The documented defaults: no timing or threshold keys (PResTimeout 200 µs, loss-of-PRes
# threshold riding through 20 ms at 1 ms).
cat >"$tmp/hold.yaml" <<YAML
bus: powerlink
cycle:
  period_us: 1000
  cpu: $cpu
powerlink:
  interface: plhd_mn
  cdc: mnobd.cdc
  nodes:
    - node_id: 1
    - node_id: 9
axes:
  - name: axis0
    node: 1
    slot: 1
shm:
  name: /ds1928d_plhd_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
YAML
"$daemon" --no-host-checks --check-config "$tmp/hold.yaml" >"$tmp/check.log" 2>&1 || fail "check-config refused it"

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" plhd_mn "$ns_cn" plhd_cn

start_cn() {  # NODE LOG
  ip netns exec "$ns_cn" "$sim" powerlink --iface plhd_cn --node "$1" --config "$tmp/hold.yaml" \
      --profile software-cn --cpu "$cpu" >"$tmp/$2" 2>&1 &
  last_pid=$!
  pids+=($last_pid)
}
start_cn 1 sim1.log
start_cn 9 sim9.log
sim9_pid=$last_pid
ip netns exec "$ns_mn" "$daemon" --config "$tmp/hold.yaml" >"$tmp/daemon.log" 2>&1 &
pids+=($!)

up=0
for ((i = 0; i < 600; i++)); do
  s=$(status)
  [ "$(node 1 "$s" | jq -r .boot)" = operational ] && [ "$(node 9 "$s" | jq -r .boot)" = operational ] &&
    [ "$(jq -r '.axes[0].state' <<<"$s")" = valid ] && { up=1; break; }
  sleep 0.05
done
[ $up = 1 ] || fail "the CNs did not reach OPERATIONAL with a valid axis within 30 s"

# ---- 1. hold ----------------------------------------------------------------------------------
s0=$(status)
c0=$(jq '.cycle.count' <<<"$s0")
sleep "$hold"
s1=$(status)
c1=$(jq '.cycle.count' <<<"$s1")
ran=$((c1 - c0))
for n in 1 9; do
  j=$(node $n "$s1")
  [ "$(jq -r .boot <<<"$j")" = operational ] || fail "node $n is not OPERATIONAL after the hold: $j"
  [ "$(jq .resets <<<"$j")" = 0 ] ||
    fail "node $n was reset $(jq .resets <<<"$j") time(s) ($(jq -r .last_reset_reason <<<"$j"))"
  eval "lost$n=$(jq .loss_of_pres.events <<<"$j")"
done
grep -q "reset by the MN" "$tmp/daemon.log" && fail "the journal names a reset"
[ "$ran" -ge $((hold * 1000 * 95 / 100)) ] || fail "only $ran cycles in ${hold} s"
a=$(ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json axes)
[ "$(jq -r '.axes[0].state' <<<"$a")" = valid ] || fail "axis not valid after the hold: $a"
[ "$(jq -r '.axes[0].time_source' <<<"$a")" = nettime ] || fail "axis not NetTime-stamped: $a"
[ "$(jq '.axes[0].format_violations' <<<"$a")" = 0 ] || fail "format violations: $a"
late=$(jq -c '{p99_us: (.cycle.wake_latency_ns.p99 / 1000), max_us: (.cycle.wake_latency_ns.max / 1000), overruns: .cycle.overruns}' \
    <<<"$(ip netns exec "$ns_mn" "$ctl" -s "$tmp/ctl.sock" --json stats 2>/dev/null)")
pass "ds1928d held node 1 (X20DS1928) and node 9 (generic, mnobd.cdc) for $ran cycles at 1 ms: 0 resets; single PRes lost: node 1 $lost1, node 9 $lost9; cycle $late"

# ---- 2. the generic CN is gone ----------------------------------------------------------------
kill -KILL "$sim9_pid"
wait "$sim9_pid" 2>/dev/null
reset=0
for ((i = 0; i < 200; i++)); do
  s=$(status)
  [ "$(node 9 "$s" | jq .resets)" -ge 1 ] 2>/dev/null && { reset=1; break; }
  sleep 0.05
done
[ $reset = 1 ] || fail "the gone CN (node 9) was not reset within 10 s"
j9=$(node 9 "$s")
grep -q "loss of PRes threshold" <<<"$(jq -r .last_reset_reason <<<"$j9")" ||
  fail "node 9 reset for another reason: $j9"
sleep 1
s=$(status)
[ "$(node 1 "$s" | jq .resets)" = 0 ] || fail "node 1 was reset too: $(node 1 "$s")"
[ "$(node 1 "$s" | jq -r .boot)" = operational ] || fail "node 1 left OPERATIONAL: $(node 1 "$s")"
pass "the gone generic CN was reset ($(jq -r .last_reset_reason <<<"$j9"), $(jq .loss_of_pres.events <<<"$j9") PRes lost); node 1 kept OPERATIONAL with 0 resets"
