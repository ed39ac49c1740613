#!/bin/bash
# PollResponse Chaining against PReq/PRes on the wire: the Managing Node (pl_mn_runner:
# PowerlinkBus on a RawLink) and 1, 4 and 16 simulated CNs (one ds1928-sim process, --count N, one
# X20DS1928 module each: a 23-byte PRes payload, a 64-byte frame with its FCS as in seed 001) in
# two network namespaces joined by a veth pair, in three modes: every CN polled with PReq/PRes,
# every CN chained (PRC), and mixed (the odd nodes PRC, the even ones PReq/PRes). Per point:
#   - from the captures (the MN's frames at the CN's end, the CNs' at the MN's end, one clock),
#     the wire time from the SoC to the last PRes of the cycle, p50 and p99 over the measured
#     complete cycles (every CN's PRes seen) at a 3 ms period (16 CNs polled with PReq/PRes and
#     their 100 µs PRes timeouts need more than 2 ms by the cycle budget), and per CN;
#   - the shortest period held: the first of the periods tried (shortest first) at which the
#     MN runs BENCH_SECONDS with all CNs OPERATIONAL, 0 resets, ≤ 0.1 % overruns and its cycle
#     work p50 within the period (a period the configuration's cycle budget refuses counts as
#     not held);
#   - beside them seed 001's per-station arithmetic for 64-byte frames at 100 Mbit/s: 12.24 µs
#     with PReq/PRes, 7.12 µs with PRC; and the ratio PRC / PReq-PRes of the measured wire time.
# The CNs are software on the same 2-core machine as the MN: their answer time, not the wire's
# 5.12 µs, dominates PReq/PRes; PRC saves the MN→CN→MN turn-around per CN.
# cyclictest in the same run is the machine's baseline.
#
# Usage: run_prc_bench.sh BUILD_DIR [--quick] [--nodes "1 4 16"]
#   BENCH_SECONDS (default 10; --quick 4) per period tried.
set -u
build=${1:?build dir}
shift
secs=${BENCH_SECONDS:-10}
node_counts="1 4 16"
while [ $# -gt 0 ]; do
  case $1 in
    --quick) secs=4 ;;
    --nodes) node_counts=$2; shift ;;
    *) echo "unknown option $1"; exit 2 ;;
  esac
  shift
done
sim=$build/tools/ds1928-sim/ds1928-sim
mn=$build/bench/powerlink/pl_mn_runner
[ "$(id -u)" = 0 ] || { echo "needs root (network namespaces, raw sockets, SCHED_FIFO)"; exit 77; }
for b in "$sim" "$mn"; do [ -x "$b" ] || { echo "$b not built"; exit 1; }; done

ns_mn=plr_mn_$$
ns_cn=plr_cn_$$
tmp=$(mktemp -d /tmp/pl_prc_bench.XXXXXX)
sim_pid=
cap_pids=()
cleanup() {
  [ -n "$sim_pid" ] && kill "$sim_pid" 2>/dev/null && wait "$sim_pid" 2>/dev/null
  for p in "${cap_pids[@]}"; do kill "$p" 2>/dev/null; wait "$p" 2>/dev/null; done
  ip netns del "$ns_mn" 2>/dev/null
  ip netns del "$ns_cn" 2>/dev/null
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM
ip netns add "$ns_mn"
ip netns add "$ns_cn"
ip link add plr_mn netns "$ns_mn" type veth peer name plr_cn netns "$ns_cn"
ip -n "$ns_mn" link set plr_mn up
ip -n "$ns_cn" link set plr_cn up

echo "# machine: $(nproc) CPUs, kernel $(uname -r), $(systemd-detect-virt 2>/dev/null || echo '?'), load $(cut -d' ' -f1-3 /proc/loadavg)"
echo "# cyclictest baseline (same run, 10 s, SCHED_FIFO 80, 1 thread per CPU, 200 us):"
cyclictest -m -q -p 80 -t "$(nproc)" -a -i 200 -l 50000 2>/dev/null | grep -E '^T:' | sed 's/^/#   /'

config() {  # N MODE PERIOD
  local n=$1 mode=$2 period=$3 prc
  printf 'bus: powerlink\ncycle:\n  period_us: %s\npowerlink:\n  interface: plr_mn\n' "$period"
  printf '  async_slot_timeout_us: 100\n  nodes:\n'
  for ((k = 1; k <= n; k++)); do
    prc=false
    [ "$mode" = prc ] && prc=true
    [ "$mode" = mixed ] && [ $((k % 2)) = 1 ] && prc=true
    printf '    - {node_id: %d, pres_timeout_us: 100, prc: %s}\n' "$k" "$prc"
  done
  printf 'axes:\n'
  for ((k = 1; k <= n; k++)); do printf '  - {name: a%d, node: %d, slot: 1}\n' "$k" "$k"; done
}

run() {  # N MODE PERIOD SECONDS CAPTURE(0/1) -> RESULT line in $tmp/mn.log
  local n=$1 mode=$2 period=$3 s=$4 capture=$5
  config "$n" "$mode" "$period" >"$tmp/b.yaml"
  cap_pids=()
  if [ "$capture" = 1 ]; then
    ip netns exec "$ns_mn" tshark -q -i plr_mn -w "$tmp/mn_end.pcapng" >"$tmp/t1.log" 2>&1 &
    cap_pids+=($!)
    ip netns exec "$ns_cn" tshark -q -i plr_cn -w "$tmp/cn_end.pcapng" >"$tmp/t2.log" 2>&1 &
    cap_pids+=($!)
    for f in "$tmp/t1.log" "$tmp/t2.log"; do
      for ((i = 0; i < 300; i++)); do grep -q "Capturing on" "$f" 2>/dev/null && break; sleep 0.1; done
    done
  fi
  ip netns exec "$ns_cn" "$sim" powerlink --iface plr_cn --node 1 --count "$n" --config "$tmp/b.yaml" \
      --rt-priority 70 --quiet >"$tmp/sim.log" 2>&1 &
  sim_pid=$!
  ip netns exec "$ns_mn" "$mn" --iface plr_mn --config "$tmp/b.yaml" --rt-priority 80 \
      --warmup 1 --duration "$s" --boot-timeout 40 >"$tmp/mn.log" 2>&1
  kill "$sim_pid" 2>/dev/null; wait "$sim_pid" 2>/dev/null; sim_pid=
  for p in "${cap_pids[@]}"; do kill -INT "$p" 2>/dev/null; wait "$p" 2>/dev/null; done
  cap_pids=()
}

field() { sed -n "s/.*[ ^]$2=\([^ ]*\).*/\1/p" "$1" | head -1; }

held() {  # PERIOD_US, from $tmp/mn.log
  local r period=$1 work50
  r=$(grep '^RESULT' "$tmp/mn.log") || return 1
  # Cycle work p50 past the period: every cycle overruns by design, whatever was counted.
  work50=$(sed -n 's/^WORK .*p50=\([0-9.]*\).*/\1/p' "$tmp/mn.log")
  awk -v w="${work50:-0}" -v p="$period" 'BEGIN { exit !(w + 0 > 0 && w + 0 <= p + 0) }' || return 1
  local all resets measured overruns
  all=$(sed -n 's/.*all_operational=\([0-9]*\).*/\1/p' <<<"$r")
  resets=$(sed -n 's/.* resets=\([0-9]*\).*/\1/p' <<<"$r")
  measured=$(sed -n 's/.*measured_cycles=\([0-9]*\).*/\1/p' <<<"$r")
  overruns=$(sed -n 's/.*overruns=\([0-9]*\).*/\1/p' <<<"$r")
  [ "$all" = 1 ] && [ "$resets" = 0 ] && [ "${measured:-0}" -gt 0 ] && [ $((overruns * 1000)) -le "$measured" ]
}

wire_time() {  # N -> "p50 p99 cycles" of SoC -> last PRes (µs), complete cycles only
  for end in mn_end cn_end; do
    tshark -r "$tmp/$end.pcapng" -Y epl -T fields -e frame.time_epoch -e epl.mtyp -e epl.src 2>/dev/null
  done | sort -t$'\t' -k1,1n | python3 -c '
import sys
n = int(sys.argv[1])
cycles, cur, soc = [], None, None
for line in sys.stdin:
    f = line.rstrip("\n").split("\t")
    if len(f) < 3 or not f[1]:
        continue
    t, mtyp, src = float(f[0]), f[1], f[2]
    if mtyp == "1":
        if cur is not None and len(cur) == n:
            cycles.append((max(cur.values()) - soc) * 1e6)
        soc, cur = t, {}
    elif mtyp == "4" and src != "240" and cur is not None:
        cur[src] = t
# the measured part: skip the first quarter (boot and warm-up)
cycles = cycles[len(cycles) // 4:]
if not cycles:
    print("- - 0"); sys.exit()
cycles.sort()
p = lambda q: cycles[min(len(cycles) - 1, int(q * len(cycles)))]
print("%.1f %.1f %d" % (p(0.5), p(0.99), len(cycles)))
' "$1"
}

periods="400 600 1000 1500 2000 3000"
declare -A wire
echo
echo "| CNs | mode | SoC→last PRes p50 / p99 (µs) | per CN p50 (µs) | seed per station (µs) | shortest period held (µs) |"
echo "|---|---|---|---|---|---|"
for n in $node_counts; do
  for mode in preq prc mixed; do
    run "$n" "$mode" 3000 "$secs" 1
    # The wire time counts complete cycles only (every CN's PRes seen), held or not.
    read -r p50 p99 cyc < <(wire_time "$n")
    note=""
    held 3000 || note=", not held at 3 ms"
    wire[$n,$mode]=$p50
    shortest="not held"
    for period in $periods; do
      run "$n" "$mode" "$period" "$secs" 0
      if held "$period"; then shortest=$period; break; fi
    done
    case $mode in preq) seed="12.24" ;; prc) seed="7.12" ;; *) seed="≈9.68 (half each)" ;; esac
    per=-
    [ "$p50" != - ] && per=$(awk -v a="$p50" -v n="$n" 'BEGIN { printf "%.1f", a / n }')
    echo "| $n | $mode | $p50 / $p99 ($cyc cycles$note) | $per | $seed | $shortest |"
  done
done
echo
echo "Ratio of the wire time SoC→last PRes, PRC / PReq-PRes (seed 001: 7.12 / 12.24 = 0.58 per station):"
for n in $node_counts; do
  a=${wire[$n,prc]} b=${wire[$n,preq]}
  if [ "$a" != - ] && [ "$b" != - ]; then
    echo "  $n CN(s): $(awk -v a="$a" -v b="$b" 'BEGIN { printf "%.2f", a / b }') ($a / $b µs)"
  else
    echo "  $n CN(s): not measured (no complete cycle captured)"
  fi
done
