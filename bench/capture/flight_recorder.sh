#!/bin/bash
# Cycle wake-up lateness of ds1928d with and without the flight recorder (flight_recorder.enabled):
# the daemon cycles against the simulator; rounds alternate a daemon started without the
# recorder and one started with it (the ring is made at start, so each round is its own daemon
# start; the simulator stays), each measured for SECONDS from a stats-reset once its axis is
# valid. Prints each round's p50/p99/max and the ratio of the median p99s (with/without), and with
# `both` (the default) a table of the two buses side by side.
#
#   bench/capture/flight_recorder.sh [both|powerlink|canio] [SECONDS] [ROUNDS]
#
# powerlink (root): ds1928d as MN and ds1928-sim as CN in two network namespaces over a veth
# pair, 1 ms cycle, SCHED_FIFO, the recorder's default 1 MiB ring. canio: the CAN-I/O virtual
# bus, 2 ms cycle. BUILD_DIR selects the build tree (default build/).
set -u
mode=${1:-both}
secs=${2:-10}
rounds=${3:-3}
here=$(cd "$(dirname "$0")" && pwd)
if [ "$mode" = both ]; then
  summary=$(mktemp /tmp/flight_bench_summary.XXXXXX)
  trap 'rm -f "$summary"' EXIT
  for m in powerlink canio; do
    if [ $m = powerlink ] && [ "$(id -u)" != 0 ]; then
      echo "powerlink: skipped (needs root: namespaces, raw sockets)"
      continue
    fi
    FLIGHT_BENCH_SUMMARY=$summary "$0" $m "$secs" "$rounds" || echo "$m: the run failed"
    echo
  done
  echo "median of $rounds rounds of ${secs} s, wake-up lateness of the cycle thread:"
  printf '%-10s %14s %14s %7s   %12s %12s   %s\n' bus "p99 without" "p99 with" ratio \
    "p50 without" "p50 with" "frames in the ring at the end"
  while read -r bus off on p50off p50on frames; do
    awk -v b="$bus" -v a="$off" -v c="$on" -v d="$p50off" -v e="$p50on" -v f="$frames" \
      'BEGIN { printf "%-10s %11.1f us %11.1f us %7.2f   %9.1f us %9.1f us   %s\n", b, a/1000, c/1000, (a > 0 ? c/a : 0), d/1000, e/1000, f }'
  done <"$summary"
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
tmp=$(mktemp -d /tmp/flight_bench.XXXXXX)
pids=()
daemon_pid=
cleanup() {
  [ -n "$daemon_pid" ] && kill "$daemon_pid" 2>/dev/null
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}" $daemon_pid; do wait "$p" 2>/dev/null; done
  ip netns del "fbmn_$tag" 2>/dev/null
  ip netns del "fbcn_$tag" 2>/dev/null
  rm -f "/dev/shm/ds1928d_fb_$tag" "/dev/shm/ds1928d_fb_$tag.wait" "/dev/shm/ds1928-vcan.fb-$tag"
  rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM

run=()
case $mode in
  powerlink)
    [ "$(id -u)" = 0 ] || { echo "powerlink mode needs root (namespaces, raw sockets)" >&2; exit 1; }
    cat >"$tmp/base.yaml" <<YAML
bus: powerlink
cycle:
  period_us: 1000
  cpu: $cpu
powerlink:
  interface: fbmn
  nodes:
    - node_id: 1
      vendor_id: 0x0000001A
axes:
  - name: axis0
    node: 1
    slot: 1
YAML
    ip netns add "fbmn_$tag" && ip netns add "fbcn_$tag" || exit 1
    ip link add fbmn netns "fbmn_$tag" type veth peer name fbcn netns "fbcn_$tag" || exit 1
    ip -n "fbmn_$tag" link set fbmn up
    ip -n "fbcn_$tag" link set fbcn up
    ip netns exec "fbcn_$tag" "$sim" powerlink --iface fbcn --node 1 --config "$tmp/base.yaml" \
        --profile software-cn --cpu "$cpu" >"$tmp/sim.log" 2>&1 &
    pids+=($!)
    run=(ip netns exec "fbmn_$tag")
    ;;
  canio)
    sed -e "s/virtual_bus: ds1928-sim/virtual_bus: fb-$tag/" -e '/^shm:/,$d' "$root/config/canio-sim.yaml" >"$tmp/base.yaml"
    "$sim" canio --virtual "fb-$tag" --config "$tmp/base.yaml" >"$tmp/sim.log" 2>&1 &
    pids+=($!)
    ;;
  *) echo "mode: both, powerlink or canio" >&2; exit 2 ;;
esac
for phase in off on; do
  cp "$tmp/base.yaml" "$tmp/$phase.yaml"
  cat >>"$tmp/$phase.yaml" <<YAML
shm:
  name: /ds1928d_fb_$tag
socket:
  path: $tmp/ctl.sock
  privileged_group: ""
metrics:
  listen: "off"
flight_recorder:
  enabled: $([ $phase = on ] && echo true || echo false)
YAML
done
c() { "${run[@]}" "$ctl" -s "$tmp/ctl.sock" "$@"; }

# One daemon with the recorder on or off, until its axis is steadily valid (POWERLINK: 2 s in a
# row, so a CN reset right after its first boot is not measured).
start_daemon() {
  "${run[@]}" "$daemon" --config "$tmp/$1.yaml" >"$tmp/daemon-$1.log" 2>&1 &
  daemon_pid=$!
  local need=40 steady=0 i
  [ "$mode" = canio ] && need=1
  for ((i = 0; i < 2400 && steady < need; i++)); do
    if [ "$(c --json status 2>/dev/null | jq -r '.axes[0].state')" = valid ]; then
      steady=$((steady + 1))
    else
      steady=0
    fi
    sleep 0.05
  done
  [ $steady -ge $need ] || { echo "axis not valid ($1)" >&2; tail "$tmp"/*.log; exit 1; }
}
stop_daemon() {
  kill "$daemon_pid" 2>/dev/null
  wait "$daemon_pid" 2>/dev/null
  daemon_pid=
}

echo "mode $mode, $rounds rounds of ${secs} s each way (a daemon start per round)"
off=() on=() p50off=() p50on=() frames=-
for ((r = 1; r <= rounds; r++)); do
  for phase in off on; do
    start_daemon $phase
    c stats-reset >/dev/null
    sleep "$secs"
    s=$(c --json status)
    w=$(jq -c '.cycle.wake_latency_ns' <<<"$s")
    [ $phase = on ] && frames=$(jq '[.flight_recorder.rings[] | .frames - .overwritten] | add' <<<"$s")
    printf "round %d recorder %-3s: wake-up p50 %6.1f us  p99 %6.1f us  max %7.1f us  (%s cycles, %s overruns)\n" \
      "$r" "$phase" "$(jq '.p50/1000' <<<"$w")" "$(jq '.p99/1000' <<<"$w")" "$(jq '.max/1000' <<<"$w")" \
      "$(jq .count <<<"$w")" "$(jq .cycle.overruns <<<"$s")"
    if [ $phase = on ]; then
      on+=("$(jq .p99 <<<"$w")") p50on+=("$(jq .p50 <<<"$w")")
    else
      off+=("$(jq .p99 <<<"$w")") p50off+=("$(jq .p50 <<<"$w")")
    fi
    stop_daemon
  done
done
median() { printf '%s\n' "$@" | sort -n | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR+1)/2] : (a[NR/2] + a[NR/2+1]) / 2}'; }
moff=$(median "${off[@]}")
mon=$(median "${on[@]}")
awk -v a="$moff" -v b="$mon" 'BEGIN { printf "median wake-up p99: without the flight recorder %.1f us, with it %.1f us, ratio %.2f\n", a/1000, b/1000, (a > 0 ? b/a : 0) }'
echo "frames held by the ring(s) at the end of the last round: $frames"
if [ -n "${FLIGHT_BENCH_SUMMARY:-}" ]; then
  echo "$mode $moff $mon $(median "${p50off[@]}") $(median "${p50on[@]}") $frames" >>"$FLIGHT_BENCH_SUMMARY"
fi
