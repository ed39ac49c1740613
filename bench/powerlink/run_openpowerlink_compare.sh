#!/bin/bash
# Side by side: ds1928d's Managing Node against openPOWERLINK V2.7.2's demo MN, both holding the
# same independent CN — openPOWERLINK's Linux demo CN (node 1, its PRes thread at SCHED_FIFO 50 on
# CPU 1) — over a veth pair between two network namespaces, booted from the same concise DCF (the
# demo's mnobd.cdc with the cycle time of the point, tests/peers/opl_cdc.py).
#
#   bench/powerlink/run_openpowerlink_compare.sh BUILD_DIR [--duration S] [--periods "1000 10000"]
#                                                [--runs N] [--out FILE]
#
# Per period: ds1928d with its cycle thread on the CN's CPU ("pinned", cycle.cpu 1) and without
# affinity ("unpinned"), each with the documented defaults (no timing or threshold keys), and
# openPOWERLINK's demo MN (which pins all its threads to CPU 1 itself: one placement). Each MN
# boots the CN to OPERATIONAL, then both veth ends are captured for S seconds (default 60):
# the MN's frames on the CN's end, the CN's on the MN's end (pl_capture_stats.py). Reported:
# SoC→PReq and PReq→PRes p50/p99 (µs), SoC→SoC min/max (µs), PReqs left unanswered, NMTResetNode
# commands on the wire (resets), PRes after OPERATIONAL in another NMT state, and the ratio of
# each ds1928d figure to openPOWERLINK's MN's at the same period (< 1: ds1928d lower).
# The peer is built by tests/peers/openpowerlink.sh (cache outside the tree). Root; ≈ (3 × S +
# 30 s) per period and run.
set -u
build=${1:?usage: run_openpowerlink_compare.sh BUILD_DIR [--duration S] [--periods LIST] [--runs N] [--out FILE]}
shift
duration=60
periods="1000 10000"
runs=1
out=""
while [ $# -gt 0 ]; do
  case $1 in
    --duration) duration=$2; shift 2 ;;
    --periods) periods=$2; shift 2 ;;
    --runs) runs=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    *) echo "unknown option $1" >&2; exit 64 ;;
  esac
done
here=$(cd "$(dirname "$0")" && pwd)
src=$(cd "$here/../.." && pwd)
daemon=$build/daemon/ds1928d
ctl=$build/tools/ds1928ctl/ds1928ctl
[ "$(id -u)" = 0 ] || { echo "needs root (network namespaces, raw sockets, SCHED_FIFO)" >&2; exit 1; }
for b in "$daemon" "$ctl"; do [ -x "$b" ] || { echo "$b not built" >&2; exit 1; }; done
for c in tshark jq python3; do command -v $c >/dev/null || { echo "$c missing (make deps-test)" >&2; exit 1; }; done
peer_env=$("$src/tests/peers/openpowerlink.sh") || exit 1
eval "$peer_env"
cn_cpu=$(($(nproc) > 1 ? 1 : 0))

tag=$$
ns_mn=plb_mn_$tag
ns_cn=plb_cn_$tag
tmp=$(mktemp -d /tmp/pl_opl_compare.XXXXXX)
pids=()
cleanup() {
  local q
  for q in "${pids[@]}"; do kill "$q" 2>/dev/null; done
  for q in "${pids[@]}"; do wait "$q" 2>/dev/null; done
  ip netns del "$ns_mn" 2>/dev/null
  ip netns del "$ns_cn" 2>/dev/null
  rm -f "/dev/shm/ds1928d_plb_$tag" "/dev/shm/ds1928d_plb_$tag.wait"
  [ -n "${KEEP_TMP:-}" ] && echo "logs in $tmp" >&2 || rm -rf "$tmp"
}
trap cleanup EXIT
trap 'exit 1' INT TERM
note() { echo "# $*" >&2; }
wait_for() {  # FILE REGEX SECONDS
  local i
  for ((i = 0; i < $3 * 20; i++)); do grep -qE "$2" "$1" 2>/dev/null && return 0; sleep 0.05; done
  return 1
}
stop_pids() {
  local q
  for q in "$@"; do kill "$q" 2>/dev/null; done
  for q in "$@"; do wait "$q" 2>/dev/null; done
  pids=()
}

ip netns add "$ns_mn" && ip netns add "$ns_cn" || exit 1
ip link add plb_mn netns "$ns_mn" type veth peer name plb_cn netns "$ns_cn" || exit 1
ip -n "$ns_mn" link set plb_mn up
ip -n "$ns_cn" link set plb_cn up

# One point: MN (ds1928d-pinned | ds1928d-unpinned | openpowerlink) at PERIOD; prints a result line
# "RESULT mn=.. period=.. <pl_capture_stats fields> ok=yes|no".
point() {
  local mn=$1 period=$2 d=$tmp/$1_$2 mn_pid cn_pid cap_cn cap_mn ok=yes
  mkdir -p "$d"
  "$src/tests/peers/opl_cdc.py" "$OPL_MNOBD_CDC" "$d/mnobd.cdc" --cycle-us "$period" || return 1
  "$src/tests/peers/opl_run.sh" "$ns_cn" -- "$OPL_DEMO_CN" -d plb_cn -n 1 >"$d/demo_cn.log" 2>&1 &
  cn_pid=$!
  pids+=($cn_pid)
  wait_for "$d/demo_cn.log" "NmtCsNotActive" 30 || { note "$mn $period: demo CN did not start"; ok=no; }
  case $mn in
    ds1928d-*)
      {
        echo "bus: powerlink"
        echo "cycle:"
        echo "  period_us: $period"
        [ "$mn" = ds1928d-pinned ] && echo "  cpu: $cn_cpu"
        echo "powerlink:"
        echo "  interface: plb_mn"
        [ -n "${DS1928D_POWERLINK_EXTRA:-}" ] && printf '%s\n' "$DS1928D_POWERLINK_EXTRA"
        echo "  cdc: mnobd.cdc"
        echo "  nodes:"
        echo "    - node_id: 1"
        echo "shm:"
        echo "  name: /ds1928d_plb_$tag"
        echo "socket:"
        echo "  path: $d/ctl.sock"
        echo "  privileged_group: \"\""
      } >"$d/mn.yaml"
      ip netns exec "$ns_mn" "$daemon" --config "$d/mn.yaml" >"$d/mn.log" 2>&1 &
      mn_pid=$!
      ;;
    openpowerlink)
      # The demo MN reads the CDC given with -c (an absolute path: it runs in its own directory).
      "$src/tests/peers/opl_run.sh" "$ns_mn" -- "$OPL_DEMO_MN" -d plb_mn -c "$d/mnobd.cdc" \
          >"$d/mn.log" 2>&1 &
      mn_pid=$!
      ;;
  esac
  pids+=($mn_pid)
  # OPERATIONAL as the CN sees it: the same witness for both MNs.
  wait_for "$d/demo_cn.log" "NmtCsReadyToOperate->NmtCsOperational" 60 ||
    { note "$mn $period: the CN did not reach OPERATIONAL"; ok=no; }
  sleep 1
  local before_resets
  before_resets=$(grep -c "NmtCsOperational->" "$d/demo_cn.log")
  ip netns exec "$ns_cn" tshark -i plb_cn -f "ether proto 0x88ab" -w "$d/cn.pcapng" >"$d/tshark_cn.log" 2>&1 &
  cap_cn=$!
  ip netns exec "$ns_mn" tshark -i plb_mn -f "ether proto 0x88ab" -w "$d/mn.pcapng" >"$d/tshark_mn.log" 2>&1 &
  cap_mn=$!
  wait_for "$d/tshark_cn.log" "Capturing on" 30 && wait_for "$d/tshark_mn.log" "Capturing on" 30 || ok=no
  sleep "$duration"
  kill -INT "$cap_cn" "$cap_mn"
  wait "$cap_cn" "$cap_mn" 2>/dev/null
  local left
  left=$(( $(grep -c "NmtCsOperational->" "$d/demo_cn.log") - before_resets ))
  local mn_cpu
  mn_cpu=$(ps -o times= -p "$mn_pid" 2>/dev/null | tr -d ' ')
  stop_pids "$mn_pid" "$cn_pid"
  local wire
  wire=$(python3 "$here/pl_capture_stats.py" "$period" "$d/cn.pcapng" "$d/mn.pcapng" 2>"$d/stats.err") || {
    note "$mn $period: capture statistics failed: $(head -c 300 "$d/stats.err")"
    wire="WIRE"
    ok=no
  }
  echo "RESULT mn=$mn period=$period ${wire#WIRE } cn_left_operational=$left ok=$ok"
}

results=$tmp/results.txt
: >"$results"
for ((r = 1; r <= runs; r++)); do
  for p in $periods; do
    for mn in ${MNS:-openpowerlink ds1928d-pinned ds1928d-unpinned}; do
      note "run $r: $mn at $p us, $duration s"
      point "$mn" "$p" >>"$results"
      tail -n1 "$results" >&2
    done
  done
done

# The table, with ratios to openPOWERLINK's MN of the same period and run.
python3 - "$results" "$duration" <<'PY' | tee ${out:+"$out"}
import sys, re
rows = []
for line in open(sys.argv[1]):
    if not line.startswith("RESULT"):
        continue
    kv = dict(x.split("=", 1) for x in line.split()[1:] if "=" in x)
    rows.append(kv)
def q(v, i):
    try:
        return float(v.split("/")[i])
    except (ValueError, IndexError, AttributeError):
        return None
def fmt(a, b):
    if a is None:
        return "-"
    return "%.0f" % a
def ratio(a, b):
    if a is None or b is None or b == 0:
        return "-"
    return "%.2f" % (a / b)
print("| period | MN | SoC→PReq p50/p99 µs (ratio) | PReq→PRes p50/p99 µs (ratio) | SoC→SoC min/max µs (max ratio) | SoC jitter p99 µs | PReq unanswered | resets | PRes not OPERATIONAL | cycles |")
print("|---|---|---|---|---|---|---|---|---|---|")
ref = {}
for kv in rows:
    if kv.get("mn") == "openpowerlink":
        ref[kv["period"]] = kv
for kv in rows:
    r = ref.get(kv["period"], {})
    sp = [q(kv.get("soc_to_preq_us"), i) for i in (0, 1)]
    rp = [q(r.get("soc_to_preq_us"), i) for i in (0, 1)]
    lp = [q(kv.get("preq_to_pres_us"), i) for i in (0, 1)]
    lr = [q(r.get("preq_to_pres_us"), i) for i in (0, 1)]
    mx = q(kv.get("soc_period_us"), 1)
    mxr = q(r.get("soc_period_us"), 1)
    mine = kv.get("mn") != "openpowerlink"
    def cell(v, rv):
        s = "%s/%s" % (fmt(v[0], None), fmt(v[1], None))
        if mine:
            s += " (%s/%s)" % (ratio(v[0], rv[0]), ratio(v[1], rv[1]))
        return s
    per = kv.get("soc_period_us", "-")
    print("| %s µs | %s | %s | %s | %s%s | %s | %s | %s | %s | %s |" % (
        kv.get("period"), kv.get("mn"), cell(sp, rp), cell(lp, lr), per,
        " (%s)" % ratio(mx, mxr) if mine else "",
        kv.get("soc_jitter_us", "-/-/-").split("/")[1] if "/" in kv.get("soc_jitter_us", "") else "-",
        kv.get("preq_unanswered", "-"), kv.get("reset_node", "-"),
        kv.get("pres_not_operational", "-"), kv.get("cycles", "-")))
PY
