#!/bin/bash
# The MN holds a CN whose PRes comes from software, under the documented defaults, and still
# detects a CN that is really gone.
#
# Two network namespaces joined by a veth pair. ds1928-sim with the software-CN profile (its
# responder blocks in the kernel, SCHED_FIFO 50, PRes after a log-normal delay with a long tail
# and not before 20 µs after the SoC) and one X20DS1928 module; the MN (pl_mn_runner: PowerlinkBus
# on a RawLink, SCHED_FIFO 80, the configuration powerlink_hold.yaml: no timing keys) on the SAME
# CPU as the CN's responder — the case where a spinning receive starved the CN.
#  1. 10^5 cycles at 1 ms measured (HOLD_SECONDS, default 100): zero loss-of-PRes resets, no
#     wrong position, no bad time stamp;
#  2. the CN is killed: the MN resets it for "loss of PRes threshold reached" (checked: the reset
#     comes after the kill, and the losses counted until it are within the threshold).
# Run time ≈ HOLD_SECONDS + 15 s.
# Usage: powerlink_hold_test.sh BUILD_DIR SOURCE_DIR   (root; 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
config=$src/tests/integration/powerlink_hold.yaml
hold=${HOLD_SECONDS:-100}
cpu=$(( $(nproc) > 1 ? 1 : 0 ))

require_root "network namespaces, veth, raw sockets, SCHED_FIFO"
require_programs "$sim" "$mn"

test_init powerlink_hold
ns_mn=plh_mn_$tag
ns_cn=plh_cn_$tag

netns_add "$ns_mn" "$ns_cn"
veth_pair "$ns_mn" plh_mn "$ns_cn" plh_cn

start_cn() {
  ip netns exec "$ns_cn" "$sim" powerlink --iface plh_cn --node 1 --config "$config" \
      --profile software-cn --cpu "$cpu" >"$tmp/$1" 2>&1 &
  sim_pid=$!
  pids+=($sim_pid)
}

# ---- 1. hold for 10^5 cycles ----------------------------------------------------------------
start_cn sim1.log
ip netns exec "$ns_mn" "$mn" --iface plh_mn --config "$config" --cpu "$cpu" --rt-priority 80 \
    --warmup 1 --duration "$hold" --boot-timeout 30 >"$tmp/mn1.log" 2>&1
rc=$?
grep '^RESULT' "$tmp/mn1.log" >"$tmp/result1.log" || fail "no RESULT from the MN (exit $rc)"
measured=$(field "$tmp/result1.log" measured_cycles)
fired=$(field "$tmp/result1.log" measured_threshold_fired)
losses=$(field "$tmp/result1.log" measured_loss_events)
[ "$rc" = 0 ] || fail "MN exit $rc (3: wrong position or stamp, 4: boot timeout)"
# Run and skipped slots (after overruns: the host's load) cover the window, less the slots of the
# last wake-up's lateness (the window ends at the first wake-up past its end).
skipped=$(field "$tmp/result1.log" measured_skipped)
late=$(sed -n 's/^WAKE .* max=\([0-9]*\).*/\1/p' "$tmp/mn1.log")
[ $(( ${measured:-0} + ${skipped:-0} )) -ge $(( hold * 1000 - ${late:-0} / 1000 - 1 )) ] ||
  fail "only $measured cycles run and ${skipped:-?} skipped in ${hold}s (expected $(( hold * 1000 )) slots)"
[ "$fired" = 0 ] || fail "$fired loss-of-PRes resets in $measured cycles ($losses PRes lost)"
pass "held the software CN for $measured cycles at 1 ms ($skipped skipped): 0 resets, $losses single PRes lost, $(grep '^LATENCY' "$tmp/mn1.log")"
kill "$sim_pid" 2>/dev/null; wait "$sim_pid" 2>/dev/null

# ---- 2. a CN that is really gone ----------------------------------------------------------
start_cn sim2.log
ip netns exec "$ns_mn" "$mn" --iface plh_mn --config "$config" --cpu "$cpu" --rt-priority 80 \
    --warmup 0 --boot-timeout 30 >"$tmp/mn2.log" 2>&1 &
mn_pid=$!
pids+=($mn_pid)
wait_for "$tmp/mn2.log" "EVENT .* all-operational" 30 || fail "CN did not reach OPERATIONAL"
sleep 1
kill -KILL "$sim_pid"
wait "$sim_pid" 2>/dev/null
echo "killed" >>"$tmp/mn2.log"
wait_for "$tmp/mn2.log" "EVENT .*node=1 boot=reset" 10 || fail "the gone CN was not reset"
kill -TERM "$mn_pid"
wait "$mn_pid"
line=$(grep -m1 "EVENT .*node=1 boot=reset" "$tmp/mn2.log")
grep -q "loss of PRes threshold" <<<"$line" || fail "reset for another reason: $line"
# The reset comes after the kill (the log is in order).
sed -n '/^killed/,$p' "$tmp/mn2.log" | grep -q "node=1 boot=reset" || fail "reset before the kill"
lost=$(sed -n 's/.*pres_losses=\([0-9]*\).*/\1/p' <<<"$line")
[ "${lost:-999}" -le 200 ] || fail "reset only after $lost lost PRes"
pass "gone CN reset for the loss-of-PRes threshold ($line)"
