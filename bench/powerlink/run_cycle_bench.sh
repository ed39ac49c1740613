#!/bin/bash
# POWERLINK cycle benchmark: the Managing Node (PowerlinkBus on a RawLink, pl_mn_runner) and 1, 4
# and 16 simulated CNs (one ds1928-sim process, --count N) in two network namespaces joined by a
# veth pair. For each node count, from 1 ms down until a period is not held, the verdict and what
# it rests on:
#   resets     CN resets by the MN in the measured window (and every CN OPERATIONAL throughout)
#   overruns   measured cycles whose work ended after the next cycle's start (the MN's cycle
#              thread, pl_mn_runner's loop), and their share of the measured cycles
#   late ct    cyclictest in the same run (alternating with the MN, same SCHED_FIFO priority, same
#              CPU, same period, same duration): the share of its wake-ups later than the slack
#              the cycle leaves, period − the cycle's measured work p50 — a cycle woken that late
#              overruns on this machine whatever the code does
#   ratio      overrun share / late share of cyclictest
#   held       0 resets, all CNs OPERATIONAL, the cycle work p50 within the period, and an
#              overrun share ≤ 1.1 × cyclictest's (no overrun at all holds whatever cyclictest
#              saw). Work p50 past the period leaves no slack: every cyclictest wake-up counts as
#              late and the overrun rule could not fail, so such a point is not held outright.
# plus SoC-to-SoC jitter p50/p99/max, PReq→PRes p50/p99 and the cycle thread's work p50/p99.
#
# Usage: run_cycle_bench.sh BUILD_DIR [--quick] [--duration S] [--nodes "1 4 16"]
#                                     [--periods "1000 500 250 200 150 100"] [--no-stop]
#   default 20 s per point (MN) plus as long for cyclictest; --quick: 5 s. --no-stop keeps going
#   down after the first period that is not held.
set -u
build=${1:?build dir}
shift
duration=20
node_counts="1 4 16"
periods="1000 500 250 200 150 100"
stop_at_first=1
while [ $# -gt 0 ]; do
  case $1 in
    --quick) duration=5 ;;
    --duration) duration=$2; shift ;;
    --nodes) node_counts=$2; shift ;;
    --periods) periods=$2; shift ;;
    --no-stop) stop_at_first=0 ;;
    *) echo "unknown option $1"; exit 2 ;;
  esac
  shift
done
sim=$build/tools/ds1928-sim/ds1928-sim
mn=$build/bench/powerlink/pl_mn_runner
[ "$(id -u)" = 0 ] || { echo "needs root (network namespaces, raw sockets, SCHED_FIFO)"; exit 77; }
for b in "$sim" "$mn"; do [ -x "$b" ] || { echo "$b not built"; exit 1; }; done
command -v cyclictest >/dev/null || { echo "cyclictest (rt-tests) is needed for the baseline"; exit 1; }

ns_mn=plb_mn_$$
ns_cn=plb_cn_$$
tmp=$(mktemp -d /tmp/pl_cycle_bench.XXXXXX)
sim_pid=
cleanup() {
  [ -n "$sim_pid" ] && kill "$sim_pid" 2>/dev/null && wait "$sim_pid" 2>/dev/null
  ip netns del "$ns_mn" 2>/dev/null
  ip netns del "$ns_cn" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM
ip netns add "$ns_mn"
ip netns add "$ns_cn"
ip link add plb_mn netns "$ns_mn" type veth peer name plb_cn netns "$ns_cn"
ip -n "$ns_mn" link set plb_mn up
ip -n "$ns_cn" link set plb_cn up

mn_cpu=1
mn_prio=80
echo "# machine: $(nproc) CPUs, kernel $(uname -r), $(systemd-detect-virt 2>/dev/null || echo '?'), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "# MN cycle thread SCHED_FIFO $mn_prio on CPU $mn_cpu; simulated CNs SCHED_FIFO 70 on CPU 0; ${duration} s per point"

# cyclictest_late PERIOD_US SLACK_US: "late total" — wake-ups of cyclictest (same priority, CPU,
# period and duration as the MN) later than SLACK_US, and all of them.
cyclictest_late() {
  local period=$1 slack=$2 loops
  loops=$(( duration * 1000000 / period ))
  cyclictest -m -q -p "$mn_prio" -a "$mn_cpu" -t 1 -i "$period" -l "$loops" -h "$period" \
      >"$tmp/ct.log" 2>/dev/null
  awk -v slack="$slack" '
    /^[0-9]+ +[0-9]+/ { lat = $1 + 0; n = $2 + 0; total += n; if (lat > slack) late += n; next }
    /^# Histogram Overflows:/ { total += $4 + 0; late += $4 + 0 }
    END { printf "%d %d\n", late, total }' "$tmp/ct.log"
}

printf '%-5s %-6s %-4s %-6s %-16s %-18s %-8s %-22s %-15s %-15s %s\n' nodes period held \
  resets "overruns (share)" "late ct (share)" ratio "soc_jitter p50/p99/max" "preq->pres p50/p99" \
  "work p50/p99" "slack"
point=0
for n in $node_counts; do
  for p in $periods; do
    point=$((point + 1))
    # The simulated CNs sleep between cycles and start polling `guard` before the next SoC;
    # the guard covers their own wake-up latency (spinning all the time would get the SCHED_FIFO
    # task throttled by the kernel).
    guard=$(( p * 6 / 10 < 200 ? p * 6 / 10 : 200 ))
    run_mn() {
      ip netns exec "$ns_cn" "$sim" powerlink --iface plb_cn --node 1 --count "$n" --quiet \
          --cpu 0 --rt-priority 70 --guard-us "$guard" >"$tmp/sim.log" 2>&1 &
      sim_pid=$!
      sleep 0.3
      # PRes timeout: generous against the wake-up latency of the simulated CN's host.
      ip netns exec "$ns_mn" "$mn" --iface plb_mn --nodes "$n" --period-us "$p" \
          --pres-timeout-us $(( p / 2 < 150 ? p / 2 : 150 )) --duration "$duration" --warmup 1 \
          --boot-timeout 20 --cpu "$mn_cpu" --rt-priority "$mn_prio" --no-check-positions \
          >"$tmp/mn.log" 2>&1
      kill "$sim_pid" 2>/dev/null; wait "$sim_pid" 2>/dev/null; sim_pid=
    }
    run_mn
    r=$(grep '^RESULT' "$tmp/mn.log")
    w=$(grep '^WORK' "$tmp/mn.log")
    get() { echo "$r" | sed -n "s/.* $1=\([0-9]*\).*/\1/p"; }
    wget() { echo "$w" | sed -n "s/.* $1=\([0-9.]*\).*/\1/p"; }
    trip() { grep "^$1" "$tmp/mn.log" | sed -n 's/.*p50=\([0-9.]*\) p99=\([0-9.]*\) max=\([0-9.]*\).*/\1\/\2\/\3/p'; }
    pair() { grep "^$1" "$tmp/mn.log" | sed -n 's/.*p50=\([0-9.]*\) p99=\([0-9.]*\).*/\1\/\2/p'; }
    op=$(get all_operational); cycles=$(get measured_cycles)
    overruns=$(wget measured_overruns); resets=$(wget measured_resets)
    work50=$(wget p50)
    slack=$(awk -v p="$p" -v w="${work50:-0}" 'BEGIN { s = int(p - w); print (s < 0 ? 0 : s) }')
    read -r ct_late ct_total < <(cyclictest_late "$p" "$slack")
    verdict=$(awk -v o="${overruns:-0}" -v c="${cycles:-0}" -v l="${ct_late:-0}" -v t="${ct_total:-0}" \
        -v op="${op:-0}" -v r="${resets:-1}" -v w="${work50:-0}" -v p="$p" 'BEGIN {
      share = c > 0 ? o / c : 1; ct = t > 0 ? l / t : 0
      ratio = (o == 0) ? "-" : (ct > 0 ? sprintf("%.2f", share / ct) : "inf")
      fits = (w + 0 > 0 && w + 0 <= p + 0)
      held = (op == 1 && r == 0 && c > 0 && fits && (o == 0 || (ct > 0 && share <= 1.1 * ct))) ? "yes" : "no"
      printf "%s %s %.4f %.4f\n", held, ratio, share * 100, ct * 100 }')
    read -r held ratio share ct_share <<<"$verdict"
    printf '%-5s %-6s %-4s %-6s %-16s %-18s %-8s %-22s %-15s %-15s %s\n' "$n" "$p" "$held" \
      "${resets:-?}" "${overruns:-?} (${share}%)" "${ct_late:-?} (${ct_share}%)" "$ratio" \
      "$(trip JITTER)" "$(pair LATENCY)" "$(pair WORK)" "$slack"
    [ "$held" = no ] && [ "$stop_at_first" = 1 ] && break
  done
done
echo "# held = 0 CN resets, all CNs OPERATIONAL throughout, cycle work p50 <= period, overrun share"
echo "#   <= 1.1 x cyclictest's late share"
echo "#   (same run, alternating, SCHED_FIFO $mn_prio, CPU $mn_cpu, same period); no overrun holds outright"
echo "# late ct = cyclictest wake-ups later than the slack (period - cycle work p50, µs, last column)"
echo "# shares in % of the measured cycles / cyclictest's loops; times in µs"
