#!/bin/bash
# Receive strategies of the Managing Node against a CN whose PRes comes from software: which one
# starves a lower-priority real-time thread on the MN's CPU, and what each costs on the wire.
#
# Two network namespaces joined by a veth pair; ds1928-sim with the software-CN profile (its
# responder blocks in the kernel and runs at SCHED_FIFO 50 on CPU --cpu) and the MN (pl_mn_runner,
# PowerlinkBus on a RawLink, SCHED_FIFO 80) on the SAME CPU — a software CN on the MN's PC, or
# any co-located real-time process. For each period and each powerlink.rx_wait (spin, block,
# busy_poll): resets (loss-of-PRes threshold events) and the MN's PReq→PRes (kernel stamps), and
# on the captures at both veth ends (pl_capture_stats.py) SoC period jitter, SoC→PReq and
# PReq→PRes. cyclictest runs first in the same run (same CPU and priority) as the baseline.
#
# Usage: run_rx_strategy_bench.sh BUILD_DIR [--duration S] [--periods "1000 200"]
#        [--waits "spin block busy_poll"] [--cpu N] [--threshold T] [--no-capture]
# --threshold: loss-of-PRes threshold for the runs (default 40: five PRes lost in a row, the
# setting of the field report; the documented default at 1 ms tolerates 20).
set -u
build=${1:?build dir}
shift
duration=20
periods="1000 200"
waits="spin block busy_poll"
cpu=1
threshold=40
capture=1
while [ $# -gt 0 ]; do
  case $1 in
    --duration) duration=$2; shift ;;
    --periods) periods=$2; shift ;;
    --waits) waits=$2; shift ;;
    --cpu) cpu=$2; shift ;;
    --threshold) threshold=$2; shift ;;
    --no-capture) capture=0 ;;
    *) echo "unknown option $1"; exit 2 ;;
  esac
  shift
done
here=$(cd "$(dirname "$0")" && pwd)
sim=$build/tools/ds1928-sim/ds1928-sim
mn=$build/bench/powerlink/pl_mn_runner
[ "$(id -u)" = 0 ] || { echo "needs root (network namespaces, raw sockets, SCHED_FIFO)"; exit 77; }
for b in "$sim" "$mn"; do [ -x "$b" ] || { echo "$b not built"; exit 1; }; done
command -v tshark >/dev/null || capture=0

ns_mn=plrx_mn_$$
ns_cn=plrx_cn_$$
tmp=$(mktemp -d /tmp/pl_rx_bench.XXXXXX)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null; done
  ip netns del "$ns_mn" 2>/dev/null
  ip netns del "$ns_cn" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM
ip netns add "$ns_mn"
ip netns add "$ns_cn"
ip link add plrx_mn netns "$ns_mn" type veth peer name plrx_cn netns "$ns_cn"
ip -n "$ns_mn" link set plrx_mn up
ip -n "$ns_cn" link set plrx_cn up

echo "# machine: $(nproc) CPUs, kernel $(uname -r), $(systemd-detect-virt 2>/dev/null || echo '?'), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "# MN (FIFO 80) and software CN responder (FIFO 50) both on CPU $cpu; loss threshold $threshold"
printf '%-6s %-9s %-9s %-7s %-8s %-20s %-20s %-20s %-20s %s\n' period rx_wait operational resets losses \
  "mn preq->pres" "wire soc_jitter" "wire soc->preq" "wire preq->pres" "cyclictest p50/p99/max"
for p in $periods; do
  # cyclictest on the same CPU at the MN's priority: what the machine gives a SCHED_FIFO thread.
  ct=$(cyclictest -m -q -p 80 -t 1 -a "$cpu" -i "$p" -l $(( 5000000 / p )) -h 4000 2>/dev/null)
  ct_avg=$(echo "$ct" | sed -n 's/^# Avg Latencies: 0*\([0-9][0-9]*\).*/\1/p')
  ct_max=$(echo "$ct" | sed -n 's/^# Max Latencies: 0*\([0-9][0-9]*\).*/\1/p')
  ct_q() {
    echo "$ct" | awk -v q="$1" '/^[0-9]+/ {n+=$2; h[$1+0]=$2}
      END {t=0; for (i=0;i<4000;i++) {t+=h[i]; if (t>=q*n) {print i; exit}} print ">4000"}'
  }
  ct_p50=$(ct_q 0.5)
  ct_p99=$(ct_q 0.99)
  timeout=$(( p >= 1000 ? 200 : 80 ))
  for w in $waits; do
    cap_pids=()
    if [ $capture = 1 ]; then
      ip netns exec "$ns_cn" dumpcap -q -i plrx_cn -f "ether proto 0x88ab" -w "$tmp/cn.pcapng" \
          >/dev/null 2>&1 &
      cap_pids+=($!)
      ip netns exec "$ns_mn" dumpcap -q -i plrx_mn -f "ether proto 0x88ab" -w "$tmp/mn.pcapng" \
          >/dev/null 2>&1 &
      cap_pids+=($!)
      pids+=("${cap_pids[@]}")
      sleep 1
    fi
    ip netns exec "$ns_cn" "$sim" powerlink --iface plrx_cn --node 1 --profile software-cn \
        --cpu "$cpu" --quiet >"$tmp/sim.log" 2>&1 &
    sim_pid=$!
    pids+=($sim_pid)
    ip netns exec "$ns_mn" "$mn" --iface plrx_mn --nodes 1 --period-us "$p" \
        --pres-timeout-us "$timeout" --loss-threshold "$threshold" --rx-wait "$w" \
        --duration "$duration" --warmup 1 --boot-timeout 30 --cpu "$cpu" --rt-priority 80 \
        --no-check-positions >"$tmp/mn.log" 2>&1
    kill "$sim_pid" 2>/dev/null; wait "$sim_pid" 2>/dev/null
    for c in "${cap_pids[@]}"; do kill "$c" 2>/dev/null; wait "$c" 2>/dev/null; done
    r=$(grep '^RESULT' "$tmp/mn.log")
    get() { echo "$r" | sed -n "s/.* $1=\([0-9]*\).*/\1/p"; }
    lat=$(grep '^LATENCY' "$tmp/mn.log" | sed -n 's/.*p50=\([0-9.]*\) p99=\([0-9.]*\) max=\([0-9.]*\).*/\1\/\2\/\3/p')
    wire="- - -"
    if [ $capture = 1 ] && [ -s "$tmp/cn.pcapng" ]; then
      wl=$(python3 "$here/pl_capture_stats.py" "$p" "$tmp/cn.pcapng" "$tmp/mn.pcapng")
      wg() { echo "$wl" | sed -n "s/.* $1=\([^ ]*\).*/\1/p"; }
      wire="$(wg soc_jitter_us) $(wg soc_to_preq_us) $(wg preq_to_pres_us)"
      rm -f "$tmp/cn.pcapng" "$tmp/mn.pcapng"
    fi
    # shellcheck disable=SC2086
    op=no
    [ "$(get all_operational)" = 1 ] && op=yes
    printf '%-6s %-9s %-9s %-7s %-8s %-20s %-20s %-20s %-20s %s\n' "$p" "$w" "$op" \
      "$(get resets)" "$(get loss_of_pres_events)" "$lat" $wire \
      "$ct_p50/$ct_p99/$ct_max (avg $ct_avg)"
  done
done
echo "# operational = the CN was OPERATIONAL at the end (else it never got there in 30 s or fell out)"
echo "# resets = NMTResetNode sent to the CN (loss-of-PRes threshold, boot step timeout) over the"
echo "#   whole run (boot + ${duration}s measured); losses = PRes lost over the whole run"
echo "# mn preq->pres: MN's send instant to the kernel's arrival stamp of the PRes (µs p50/p99/max)"
echo "# wire: from captures at both veth ends (pl_capture_stats.py), µs p50/p99/max"
