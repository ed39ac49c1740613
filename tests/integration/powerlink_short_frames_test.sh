#!/bin/bash
# Unpadded frames between network namespaces: software senders on veth/TAP links put frames
# shorter than Ethernet's 60 bytes on the wire. 54-byte SoC/SoA (14-byte Ethernet header + 40
# bytes of POWERLINK, as an MN stack on Linux sends them) and PRes frames are sent from a raw
# socket (pl_send_frames.py) to
#  1. ds1928-sim: every complete one is accepted and counted (short=, soc=, soa=), the CN answers
#     a 54-byte IdentRequest; frames cut inside their message are refused (bad=);
#  2. the Managing Node (pl_mn_runner): accepted and counted (short_frames=), foreign SoC/SoA as
#     unexpected, PRes of a node not polled as stale; cut frames counted as invalid.
# Run time ≈ 5 s.   Usage: powerlink_short_frames_test.sh BUILD_DIR SOURCE_DIR  (root; 77 = skip)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
sender=$src/tests/integration/pl_send_frames.py

require_root "network namespaces, veth, raw sockets"
require_programs "$sim" "$mn"

test_init powerlink_short
ns_a=plsf_a_$tag
ns_b=plsf_b_$tag
FAIL_LOG_LINES=20
expect() {  # FILE FIELD VALUE WHAT
  local v
  v=$(field "$1" "$2")
  [ "$v" = "$3" ] || fail "$4: $2=$v, expected $3"
}

netns_add "$ns_a" "$ns_b"
veth_pair "$ns_a" plsf_a "$ns_b" plsf_b

# ---- 1. ds1928-sim as the receiver -----------------------------------------------------------
ip netns exec "$ns_b" "$sim" powerlink --iface plsf_b --node 1 --rt-priority 0 \
    >"$tmp/sim.log" 2>&1 &
sim_pid=$!
pids+=($sim_pid)
wait_for "$tmp/sim.log" "^node 1: .* on plsf_b" 20 || fail "ds1928-sim did not start"
ip netns exec "$ns_a" python3 "$sender" plsf_a soc:1:35 soa-none:1:22 soc:20:54 soa-none:20:54 \
    --probe-ident --timeout 20 >"$tmp/send_cn.log" 2>&1 || fail "sender (to the CN)"
probes=$(sed -n 's/^probes \([0-9]*\)/\1/p' "$tmp/send_cn.log")
kill -TERM "$sim_pid"
wait "$sim_pid"
grep -q "NOT_ACTIVE -> PRE_OPERATIONAL_1" "$tmp/sim.log" || fail "CN did not take the 54-byte SoA"
stats=$tmp/sim_stats.log
grep "^node 1 stats:" "$tmp/sim.log" >"$stats" || fail "no statistics from ds1928-sim"
expect "$stats" soc 20 "ds1928-sim SoC count"
expect "$stats" soa $((20 + probes)) "ds1928-sim SoA count"
expect "$stats" short $((40 + probes)) "ds1928-sim short frames"
expect "$stats" bad 2 "ds1928-sim refused (35-byte SoC, 22-byte SoA)"
pass "ds1928-sim: $((40 + probes)) frames of 54 bytes accepted, IdentResponse after $probes probe(s), 2 truncated refused"

# ---- 2. the Managing Node as the receiver ----------------------------------------------------
ip netns exec "$ns_a" "$mn" --iface plsf_a --nodes 1 --rt-priority 0 --boot-timeout 60 \
    --warmup 0 >"$tmp/mn.log" 2>&1 &
mn_pid=$!
pids+=($mn_pid)
ip netns exec "$ns_b" python3 "$sender" plsf_b soc:1:35 soc:20:54 soa-none:20:54 pres:5:54 \
    --after-soa-from 240 --answer-ident --timeout 20 >"$tmp/send_mn.log" 2>&1 ||
  fail "sender (to the MN)"
wait_for "$tmp/mn.log" "EVENT .*node=1 boot=wait_pre_operational_2" 20 ||
  fail "MN did not take node 1's IdentResponse"
kill -TERM "$mn_pid"
wait "$mn_pid"
grep "^RESULT" "$tmp/mn.log" >"$tmp/mn_result.log" || fail "no RESULT from the MN"
expect "$tmp/mn_result.log" short_frames 45 "MN short frames (20 SoC + 20 SoA + 5 PRes)"
expect "$tmp/mn_result.log" invalid_frames 1 "MN refused (35-byte SoC)"
expect "$tmp/mn_result.log" unexpected_frames 40 "MN: SoC/SoA of another MN"
expect "$tmp/mn_result.log" stale_pres_dropped 5 "MN: PRes of a node not polled"
pass "MN: 45 frames of 54 bytes accepted and counted, 1 truncated refused"
