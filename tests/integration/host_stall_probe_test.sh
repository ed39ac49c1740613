#!/bin/bash
# bench/cycle/host_stall_probe finds a stop of every CPU: the probe is stopped (SIGSTOP) for
# 300 ms once it says it measures, which to each of its SCHED_FIFO threads looks as a host not
# running its vCPU does. Each CPU must report one stall of at least 250 ms that spans the moment
# of the SIGCONT, in CLOCK_REALTIME (the captures' clock), the summary must count them as a stop
# of the whole machine, and every line must have the documented form. A stall of the host besides
# adds lines, never removes the one of the stop: the test cannot pass or fail by the host's luck.
# Usage: host_stall_probe_test.sh BUILD_DIR SOURCE_DIR   (root; 77 = skipped)
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"

require_root "SCHED_FIFO 99"
probe=$build/bench/cycle/host_stall_probe
require_programs "$probe"
require_tools python3

test_init host_stall_probe
"$probe" --out "$tmp/stalls.txt" >"$tmp/probe.log" 2>&1 &
probe_pid=$!
track "$probe_pid"
wait_for "$tmp/probe.log" '^probing [0-9]+ CPU' 10 || fail "the probe never said it measures"
cpus=$(sed -n 's/^probing \([0-9]*\) CPU.*/\1/p' "$tmp/probe.log")

kill -STOP "$probe_pid"
sleep 0.3
cont_at=$(date +%s.%N)
kill -CONT "$probe_pid"
sleep 0.05
kill -INT "$probe_pid"
wait "$probe_pid" || fail "the probe failed: $(cat "$tmp/probe.log")"

python3 - "$tmp/stalls.txt" "$cpus" "$cont_at" <<'PY' || fail "the stop was not found"
import sys
path, cpus, cont_at = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
found = {}
for n, line in enumerate(open(path), 1):
    f = line.split()
    if len(f) != 4:
        sys.exit(f"line {n}: {line!r}: not CPU START END LATE_MS")
    cpu, start, end, late = int(f[0]), float(f[1]), float(f[2]), float(f[3])
    if not (start < end and abs((end - start) * 1e3 - late) < 0.01):
        sys.exit(f"line {n}: {line!r}: LATE_MS is not END - START")
    if late >= 250 and start <= cont_at <= end:
        found[cpu] = late
print(f"the stop, per CPU (ms): {found}")
if len(found) != cpus:
    sys.exit(f"{len(found)} of {cpus} CPUs report the 300 ms stop")
PY
grep -qE "^stalls overlapping a stall of every other CPU: ([0-9]+) of" "$tmp/probe.log" ||
  fail "no summary line"
whole=$(sed -n 's/^stalls overlapping a stall of every other CPU: \([0-9]*\) of.*/\1/p' "$tmp/probe.log")
if ((cpus > 1 && whole < cpus)); then
  fail "the summary counts $whole stalls as the whole machine's, the stop alone is $cpus"
fi
cat "$tmp/probe.log"
pass "host_stall_probe: a 300 ms stop of the probe found on each of its $cpus CPU(s)"
