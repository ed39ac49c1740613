#!/bin/bash
# ds1928ctl doctor on this machine, against config/powerlink.yaml and config/simulated.yaml:
# every check line is PASS/WARN/FAIL, --json parses and agrees with the text, the exit code says
# whether a check failed, an unreadable configuration is a usage error (2), and --measure runs the
# cycle engine, reports its wake-up figures and judges them (measured_wakeup) as they say.
# Usage: doctor_machine_test.sh BUILD_DIR SOURCE_DIR
set -u
ctl=${1:?build dir}/tools/ds1928ctl/ds1928ctl
src=${2:?source dir}
[ -x "$ctl" ] || { echo "FAIL: $ctl not built"; exit 1; }
command -v jq >/dev/null || { echo "SKIP: jq not installed"; exit 77; }
tmp=$(mktemp -d /tmp/doctor_machine.XXXXXX)
trap 'rm -rf "$tmp"' EXIT
fail() { echo "FAIL: $*"; exit 1; }

for cfg in powerlink simulated; do
  rc=0
  "$ctl" doctor --config "$src/config/$cfg.yaml" >"$tmp/$cfg.txt" 2>&1 || rc=$?
  cat "$tmp/$cfg.txt"
  grep -qE '^(PASS|WARN|FAIL)  preemption ' "$tmp/$cfg.txt" || fail "$cfg: no preemption line"
  n=$(grep -cE '^(PASS|WARN|FAIL)  ' "$tmp/$cfg.txt")
  rcj=0
  "$ctl" doctor --config "$src/config/$cfg.yaml" --json >"$tmp/$cfg.json" 2>&1 || rcj=$?
  [ "$(jq '.checks | length' "$tmp/$cfg.json")" = "$n" ] || fail "$cfg: --json has another number of checks than the text ($n)"
  fails=$(jq '.summary.fail' "$tmp/$cfg.json")
  [ "$fails" = "$(grep -c '^FAIL  ' "$tmp/$cfg.txt")" ] || fail "$cfg: summary disagrees with the text"
  want=0; [ "$fails" -gt 0 ] && want=1
  [ $rc = $want ] && [ $rcj = $want ] || fail "$cfg: exit $rc/$rcj with $fails failed checks (expected $want)"
  jq -e '.checks | all(.verdict == "PASS" or .fix != null)' "$tmp/$cfg.json" >/dev/null ||
    fail "$cfg: a WARN/FAIL without its fix"
  echo "ok: $cfg: $n checks, $fails failed, exit $rc"
done
grep -q "PASS  irq_affinity    no bus interface" "$tmp/simulated.txt" || fail "simulated: irq_affinity line"

# An interface this machine does not have: start refuses it, so the doctor FAILs (exit 1) naming
# it, and asks ethtool nothing about it.
sed 's/^\(  interface:\) eth1 /\1 ds1928none0 /' "$src/config/powerlink.yaml" >"$tmp/nonic.yaml"
grep -q "interface: ds1928none0 " "$tmp/nonic.yaml" || fail "could not derive nonic.yaml"
rc=0
"$ctl" doctor --config "$tmp/nonic.yaml" >"$tmp/nonic.txt" 2>&1 || rc=$?
[ $rc = 1 ] && grep -q "^FAIL  irq_affinity    ds1928none0: no such interface" "$tmp/nonic.txt" &&
  ! grep -qE "^(PASS|WARN|FAIL)  (coalescing|eee) " "$tmp/nonic.txt" ||
  fail "a missing interface: exit $rc: $(cat "$tmp/nonic.txt")"
echo "ok: a missing interface FAILs (exit 1): $(grep '^FAIL  irq_affinity' "$tmp/nonic.txt")"

rc=0
"$ctl" doctor --config "$tmp/nothing.yaml" >"$tmp/bad.txt" 2>&1 || rc=$?
[ $rc = 2 ] && grep -q "nothing.yaml" "$tmp/bad.txt" || fail "a missing configuration: exit $rc: $(cat "$tmp/bad.txt")"
echo "ok: a missing configuration is a usage error naming the file"

"$ctl" doctor --config "$src/config/simulated.yaml" --measure 1 --json >"$tmp/measure.json" 2>&1 || true
jq -e '.measure.cycles > 500 and .measure.wake_latency_ns.p99 > 0 and .measure.wake_latency_ns.max >= .measure.wake_latency_ns.p99' \
  "$tmp/measure.json" >/dev/null || fail "--measure: $(cat "$tmp/measure.json")"
# The measurement is judged as one more check, by the figures it reports beside it.
jq -e '[.checks[] | select(.name == "measured_wakeup")] | length == 1' "$tmp/measure.json" >/dev/null ||
  fail "--measure: no measured_wakeup check: $(jq -c .checks "$tmp/measure.json")"
verdict=$(jq -r '.checks[] | select(.name == "measured_wakeup") | .verdict' "$tmp/measure.json")
want=$(jq -r 'if .measure.wake_latency_ns.max < .measure.period_us * 1000 and .measure.overruns == 0
              then "PASS" else "WARN" end' "$tmp/measure.json")
[ "$verdict" = "$want" ] || fail "--measure: measured_wakeup is $verdict, the figures say $want"
echo "ok: --measure 1: $(jq -c '.measure | {cycles, overruns, wake_latency_ns, rt_status}' "$tmp/measure.json"), measured_wakeup $verdict"
echo "PASS: doctor_machine"
