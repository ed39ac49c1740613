#!/bin/bash
# Cycle wake-up lateness of ds1928d with and without a capture running (ds1928ctl capture):
# the daemon cycles against the simulator; rounds of SECONDS each alternate "no capture" and
# "capture to /dev/null", the daemon's wake-up histogram reset at the start of each (stats-reset)
# and read at its end. Prints each round's p50/p99/max and the ratio of the median p99s; with
# `both` (the default) both buses one after the other, then a table of the two side by side.
#
#   bench/capture/run.sh [both|powerlink|canio] [SECONDS] [ROUNDS]
#
# powerlink (root): ds1928d as MN and ds1928-sim as CN in two network namespaces over a veth
# pair, 1 ms cycle, SCHED_FIFO. canio: the CAN-I/O virtual bus, 2 ms cycle (no root needed;
# SCHED_FIFO when root). both: powerlink (skipped without root), then canio. BUILD_DIR selects
# the build tree (default build/).
set -u
mode=${1:-both}
secs=${2:-10}
rounds=${3:-3}
here=$(cd "$(dirname "$0")" && pwd)
if [ "$mode" = both ]; then
  # Each bus in a run of its own (own daemon, simulator, clean-up); each appends its medians to
  # the summary, printed side by side at the end.
  summary=$(mktemp /tmp/capture_bench_summary.XXXXXX)
  trap 'rm -f "$summary"' EXIT
  for m in powerlink canio; do
    if [ $m = powerlink ] && [ "$(id -u)" != 0 ]; then
      echo "powerlink: skipped (needs root: namespaces, raw sockets)"
      continue
    fi
    CAPTURE_BENCH_SUMMARY=$summary "$0" $m "$secs" "$rounds" || echo "$m: the run failed"
    echo
  done
  echo "median of $rounds rounds of ${secs} s, wake-up lateness of the cycle thread:"
  printf '%-10s %12s %12s %7s   %12s %12s   %s\n' bus "p99 without" "p99 with" ratio \
    "p50 without" "p50 with" "captured frames/s, dropped"
  while read -r bus off on p50off p50on fps dropped; do
    awk -v b="$bus" -v a="$off" -v c="$on" -v d="$p50off" -v e="$p50on" -v f="$fps" -v g="$dropped" \
      'BEGIN { printf "%-10s %9.1f us %9.1f us %7.2f   %9.1f us %9.1f us   %s, %s\n", b, a/1000, c/1000, (a > 0 ? c/a : 0), d/1000, e/1000, f, g }'
  done < "$summary"
  exit 0
fi
root=$(cd "$here/../.." && pwd)
build=${BUILD_DIR:-$root/build}
sim=$build/tools/ds1928-sim/ds1928-sim
daemon=$build/daemon/ds1928d
ctl=$build/tools/ds1928ctl/ds1928ctl
for bin in "$sim" "$daemon" "$ctl"; do [ -x "$bin" ] || { echo "$bin not built" >&2; exit 1; }; done
command -v jq >/dev/null || { echo "needs jq" >&2; exit 1; }
cpu=$(( $(nproc) > 1 ? 1 : 0 ))
tag=$$
tmp=$(mktemp -d /tmp/capture_bench.XXXXXX)
pids=()
cleanup() {
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null; done
  ip netns del "cbmn_$tag" 2>/dev/null
  ip netns del "cbcn_$tag" 2>/dev/null
  rm -f "/dev/shm/ds1928d_cb_$tag" "/dev/shm/ds1928-vcan.cb-$tag"
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

run=()
case $mode in
  powerlink)
    [ "$(id -u)" = 0 ] || { echo "powerlink mode needs root (namespaces, raw sockets)" >&2; exit 1; }
    cat >"$tmp/cfg.yaml" <<YAML
bus: powerlink
cycle:
  period_us: 1000
  cpu: $cpu
powerlink:
  interface: cbmn
  nodes:
    - node_id: 1
      vendor_id: 0x0000001A
axes:
  - name: axis0
    node: 1
    slot: 1
YAML
    ip netns add "cbmn_$tag" && ip netns add "cbcn_$tag" || exit 1
    ip link add cbmn netns "cbmn_$tag" type veth peer name cbcn netns "cbcn_$tag" || exit 1
    ip -n "cbmn_$tag" link set cbmn up
    ip -n "cbcn_$tag" link set cbcn up
    ip netns exec "cbcn_$tag" "$sim" powerlink --iface cbcn --node 1 --config "$tmp/cfg.yaml" \
        --profile software-cn --cpu "$cpu" >"$tmp/sim.log" 2>&1 &
    pids+=($!)
    run=(ip netns exec "cbmn_$tag")
    ;;
  canio)
    sed -e "s/virtual_bus: ds1928-sim/virtual_bus: cb-$tag/" -e '/^shm:/,$d' "$root/config/canio-sim.yaml" >"$tmp/cfg.yaml"
    "$sim" canio --virtual "cb-$tag" --config "$tmp/cfg.yaml" >"$tmp/sim.log" 2>&1 &
    pids+=($!)
    ;;
  *) echo "mode: both, powerlink or canio" >&2; exit 2 ;;
esac
cat >>"$tmp/cfg.yaml" <<YAML
shm:
  name: /ds1928d_cb_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
YAML
"${run[@]}" "$daemon" --config "$tmp/cfg.yaml" >"$tmp/daemon.log" 2>&1 &
pids+=($!)
c() { "${run[@]}" "$ctl" -s "$tmp/ctl.sock" "$@"; }
# POWERLINK: valid for 2 s in a row, so a CN that is reset once right after its first boot is not
# measured. CAN-I/O: valid once (the node configured); on a loaded machine the simulator process
# misses answers, and its axis turns stale for a cycle now and then without anything restarting.
need=40
[ "$mode" = canio ] && need=1
steady=0
for ((i = 0; i < 2400 && steady < need; i++)); do
  if [ "$(c --json status 2>/dev/null | jq -r '.axes[0].state')" = valid ]; then
    steady=$((steady + 1))
  else
    steady=0
  fi
  sleep 0.05
done
[ $steady -ge $need ] || { echo "axis not valid" >&2; tail "$tmp"/*.log; exit 1; }
echo "mode $mode, $rounds rounds of ${secs} s each way; rt: $(c --json status | jq -r .daemon.rt_status)"

off=() on=() p50off=() p50on=() fps=() drops=0
for ((r = 1; r <= rounds; r++)); do
  for phase in off on; do
    c stats-reset >/dev/null
    if [ $phase = on ]; then
      c --json capture -w /dev/null --duration "$secs" >"$tmp/cap.json" || { echo "capture failed" >&2; exit 1; }
      frames=$(jq .capture.frames "$tmp/cap.json")
      dropped=$(jq '[.capture.interfaces[].dropped] | add' "$tmp/cap.json")
      fps+=("$(jq '.capture.frames / .capture.duration_s | floor' "$tmp/cap.json")")
      drops=$((drops + dropped))
    else
      sleep "$secs"
      frames=- dropped=-
    fi
    w=$(c --json stats | jq -c '.cycle.wake_latency_ns')
    p99=$(jq .p99 <<<"$w")
    printf "round %d capture %-3s: wake-up p50 %6.1f us  p99 %6.1f us  max %7.1f us  (%s cycles; captured %s, dropped %s)\n" \
      "$r" "$phase" "$(jq '.p50/1000' <<<"$w")" "$(jq '.p99/1000' <<<"$w")" "$(jq '.max/1000' <<<"$w")" \
      "$(jq .count <<<"$w")" "$frames" "$dropped"
    if [ $phase = on ]; then
      on+=("$p99") p50on+=("$(jq .p50 <<<"$w")")
    else
      off+=("$p99") p50off+=("$(jq .p50 <<<"$w")")
    fi
  done
done
median() { printf '%s\n' "$@" | sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
moff=$(median "${off[@]}")
mon=$(median "${on[@]}")
awk -v a="$moff" -v b="$mon" 'BEGIN { printf "median wake-up p99: without capture %.1f us, with capture %.1f us, ratio %.2f\n", a/1000, b/1000, (a > 0 ? b/a : 0) }'
if [ -n "${CAPTURE_BENCH_SUMMARY:-}" ]; then
  echo "$mode $moff $mon $(median "${p50off[@]}") $(median "${p50on[@]}") $(median "${fps[@]}") $drops" >>"$CAPTURE_BENCH_SUMMARY"
fi
