#!/bin/bash
# Round trip PReq → PRes over a veth pair between two network namespaces, for each receive
# strategy of RawLink. Usage: run_rx_latency.sh BUILD_DIR [COUNT] [PERIOD_US]
# Needs root. Baseline (issue 6, this kind of machine): blocking ≈ 57 µs median, MSG_DONTWAIT
# polling ≈ 3.3 µs, TPACKET_V2 ring ≈ 2.7 µs.
set -euo pipefail
build=${1:?build dir}
count=${2:-20000}
period=${3:-200}
bin=$build/bench/powerlink/pl_rx_latency
[ "$(id -u)" = 0 ] || { echo "needs root (network namespaces, raw sockets)"; exit 77; }
ns_a=plrx_mn_$$
ns_b=plrx_cn_$$
cleanup() {
  [ -n "${echo_pid:-}" ] && kill "$echo_pid" 2>/dev/null && wait "$echo_pid" 2>/dev/null || true
  ip netns del "$ns_a" 2>/dev/null || true
  ip netns del "$ns_b" 2>/dev/null || true
}
trap cleanup EXIT
ip netns add "$ns_a"
ip netns add "$ns_b"
ip link add plrx_a netns "$ns_a" type veth peer name plrx_b netns "$ns_b"
ip -n "$ns_a" link set plrx_a up
ip -n "$ns_b" link set plrx_b up
sleep 0.2  # carrier settles
echo "cyclictest-free host view: $(nproc) CPUs, kernel $(uname -r)"
for mode in ${MODES:-blocking busy-poll ring}; do
  ip netns exec "$ns_b" "$bin" echo --iface plrx_b --mode "$mode" --rt 70 --cpu 1 --period-us "$period" &
  echo_pid=$!
  sleep 0.3
  ip netns exec "$ns_a" "$bin" ping --iface plrx_a --mode "$mode" --rt 80 --cpu 0 \
      --count "$count" --period-us "$period"
  kill "$echo_pid"; wait "$echo_pid" 2>/dev/null || true
  echo_pid=
done
echo "baseline (issue 6): blocking ~57 us, busy-poll ~3.3 us, ring ~2.7 us median"
