#!/bin/bash
# ds1928d's command line as a user meets it first, no bus touched:
#  1. --help names the default configuration file;
#  2. -c FILE --print-config prints the effective configuration and exits without starting (no
#     shared memory, no socket); the printed text loads back (--check-config) and prints the same;
#     the verdict line goes to stderr, not into the YAML; the same for every shipped example;
#  3. --check-config checks this host as start would: a missing POWERLINK/CAN interface, a missing
#     shm.group / socket.group, an interface with an IP address (lo) unless
#     powerlink.allow_shared_interface — each named; --no-host-checks checks the file alone; a
#     valid file's verdict says what is left to the start;
#     config/simulated.yaml and config/canio-sim.yaml (make run, make run-canio) share no
#     socket, shared memory or metrics port;
#  4. start with a missing shm.group names the group;
#  5. `ds1928d -c FILE | head -1`: the pipe's reader leaves, the daemon stops cleanly (exit 0, the
#     shared memory and the socket removed), not killed by SIGPIPE (141).
set -u
. "${2:?source dir}/tests/lib/netns.sh"
use_trees "$1" "$2"
require_programs "$daemon"
test_init ds1928d-cli

shm=/ds1928d-cli-$tag
sim_yaml() {
  cat >"$tmp/$1.yaml" <<YAML
bus: simulated
cycle: {period_us: 1000, hold_cpu_dma_latency: false}
axes: [{name: x}]
shm: {name: $shm${2:+, group: $2}}
socket: {path: $tmp/control.sock}
YAML
}

# 1
"$daemon" --help >"$tmp/help.out" 2>&1 || fail "--help exits non-zero"
grep -q "default /etc/ds1928d/ds1928d.yaml" "$tmp/help.out" || fail "--help does not name the default configuration"
pass "--help names /etc/ds1928d/ds1928d.yaml"

# 2
sim_yaml sim
rc=0
timeout 20 "$daemon" -c "$tmp/sim.yaml" --print-config >"$tmp/printed.yaml" 2>"$tmp/print.err" || rc=$?
[ "$rc" = 0 ] || fail "-c FILE --print-config: exit $rc (124: it started and ran)"
[ ! -e "/dev/shm${shm}" ] || fail "-c FILE --print-config created the shared memory $shm: it started"
[ ! -e "$tmp/control.sock" ] || fail "-c FILE --print-config created the control socket: it started"
grep -q "sim.yaml: ok (bus simulated" "$tmp/print.err" || fail "no verdict on stderr: $(cat "$tmp/print.err")"
grep -q ": ok (" "$tmp/printed.yaml" && fail "the verdict line is in the printed YAML"
grep -q "^bus: simulated" "$tmp/printed.yaml" || fail "no configuration printed"
pass "-c FILE --print-config prints and exits: no shared memory, no socket"

loads_back() {  # FILE [OPTION]: its printed configuration loads back and prints the same
  local name
  name=$(basename "$1" .yaml)
  "$daemon" --check-config "$1" --print-config ${2:-} >"$tmp/$name.p1.yaml" 2>"$tmp/$name.p1.err" ||
    fail "$1: --print-config refused it: $(cat "$tmp/$name.p1.err")"
  "$daemon" --check-config "$tmp/$name.p1.yaml" ${2:-} >"$tmp/$name.check.out" 2>&1 ||
    fail "$1: the printed configuration does not load back: $(cat "$tmp/$name.check.out")"
  "$daemon" --check-config "$tmp/$name.p1.yaml" --print-config ${2:-} >"$tmp/$name.p2.yaml" 2>/dev/null ||
    fail "$1: the printed configuration does not print"
  # The first line names the file it was printed from.
  cmp -s <(tail -n +2 "$tmp/$name.p1.yaml") <(tail -n +2 "$tmp/$name.p2.yaml") ||
    fail "$1: printed twice, not the same: $(diff "$tmp/$name.p1.yaml" "$tmp/$name.p2.yaml" | head -5)"
}
loads_back "$tmp/sim.yaml"
loads_back "$src/config/simulated.yaml"
loads_back "$src/config/canio-sim.yaml"
# The shipped POWERLINK and CAN examples name interfaces of their machine, not of this one.
loads_back "$src/config/powerlink.yaml" --no-host-checks
loads_back "$src/config/canio.yaml" --no-host-checks
pass "--check-config F --print-config loads back and prints the same (5 files)"

# make run and make run-canio run side by side: their configurations share no control socket,
# shared memory or metrics port (else the second start fails with "Address already in use").
shared_names() {  # FILE: socket.path, shm.name, metrics.listen of its printed configuration
  awk '/^[a-z_]+:/ { sec = $1; sub(":.*", "", sec) }
       (sec == "socket" && $1 == "path:") || (sec == "shm" && $1 == "name:") ||
       (sec == "metrics" && $1 == "listen:") { print sec "." $1 " " $2 }' "$1"
}
shared_names "$tmp/simulated.p1.yaml" >"$tmp/run.names"
shared_names "$tmp/canio-sim.p1.yaml" >"$tmp/run-canio.names"
[ "$(wc -l <"$tmp/run.names")" = 3 ] && [ "$(wc -l <"$tmp/run-canio.names")" = 3 ] ||
  fail "socket.path, shm.name, metrics.listen not all printed: $(cat "$tmp/run.names" "$tmp/run-canio.names")"
common=$(comm -12 <(sort "$tmp/run.names") <(sort "$tmp/run-canio.names") | tr '\n' ' ')
[ -z "$common" ] || fail "config/simulated.yaml and config/canio-sim.yaml share $common"
pass "make run's and make run-canio's configurations share no socket, shared memory or port"

# config/simulated.yaml is "every key" of the sections the simulated bus uses: each key the
# effective configuration prints there is written in the file.
section_keys() {  # FILE: section.key for the two-space keys of the common sections
  awk '/^[a-z_]+:/ { sec = $1; sub(":.*", "", sec) }
       /^  [a-z_]+:/ && sec ~ /^(log_level|cycle|shm|socket|metrics|capture|flight_recorder|topology)$/ {
         k = $1; sub(":.*", "", k); print sec "." k }' "$1" | sort -u
}
section_keys "$tmp/simulated.p1.yaml" >"$tmp/printed.keys"
section_keys "$src/config/simulated.yaml" >"$tmp/file.keys"
missing=$(comm -23 "$tmp/printed.keys" "$tmp/file.keys" | tr '\n' ' ')
[ "$(wc -l <"$tmp/printed.keys")" -gt 30 ] || fail "too few keys printed: $(cat "$tmp/printed.keys")"
[ -z "$missing" ] || fail "config/simulated.yaml lacks keys the daemon has: $missing"
pass "config/simulated.yaml has every key of its sections ($(wc -l <"$tmp/printed.keys") keys)"

# 3
host_check() {  # NAME EXPECTED_RC REGEX [OPTION]: --check-config NAME.yaml
  local rc=0
  "$daemon" --check-config "$tmp/$1.yaml" ${4:-} >"$tmp/$1.out" 2>&1 || rc=$?
  [ "$rc" = "$2" ] || fail "--check-config $1.yaml ${4:-}: exit $rc, expected $2: $(cat "$tmp/$1.out")"
  grep -qE "$3" "$tmp/$1.out" || fail "--check-config $1.yaml ${4:-}: no /$3/ in: $(cat "$tmp/$1.out")"
}
pl_yaml() {
  cat >"$tmp/$1.yaml" <<YAML
bus: powerlink
cycle: {period_us: 1000}
powerlink:
  interface: $2
  allow_shared_interface: ${3:-false}
  nodes: [{node_id: 1}]
axes: [{name: x, node: 1, slot: 1}]
shm: {name: $shm}
socket: {path: $tmp/control.sock}
YAML
}
pl_yaml nosuchif nosuchif$tag
host_check nosuchif 2 "powerlink.interface: no network interface 'nosuchif$tag' on this host"
host_check nosuchif 0 "this host not checked" --no-host-checks
pl_yaml lo lo
host_check lo 2 "powerlink.interface: 'lo' looks like a port of an IP network.*127\.0\.0\.1/8"
pl_yaml lo_allowed lo true
host_check lo_allowed 0 "left to the start.*raw socket \(root or CAP_NET_RAW\)"
cat >"$tmp/can.yaml" <<YAML
bus: canio
canio: {interface: nosuchcan$tag}
axes: [{name: x, node: 1, function_model: 254, module: {output_mtu: 5, input_mtu: 5}}]
shm: {name: $shm}
socket: {path: $tmp/control.sock}
YAML
host_check can 2 "canio.interface: no network interface 'nosuchcan$tag'"
sim_yaml nogroup "nosuchgrp$tag"
host_check nogroup 2 "shm.group: no group 'nosuchgrp$tag' on this host"
sed "s|socket: {path: \(.*\)}|socket: {path: \1, group: nosuchsock$tag}|" "$tmp/sim.yaml" >"$tmp/nosockgroup.yaml"
host_check nosockgroup 2 "socket.group: no group 'nosuchsock$tag'"
host_check sim 0 "left to the start \(they need the running system\)"
pass "--check-config: interfaces, groups and shared interfaces named; --no-host-checks"

# 4
rc=0
timeout 30 "$daemon" -c "$tmp/nogroup.yaml" >"$tmp/start_nogroup.log" 2>&1 || rc=$?
[ "$rc" = 1 ] || fail "start with a missing shm.group: exit $rc, expected 1"
grep -q "shm.group: no group 'nosuchgrp$tag'" "$tmp/start_nogroup.log" ||
  fail "start's error does not name the shm group"
[ ! -e "/dev/shm${shm}" ] || fail "the refused start left $shm behind"
pass "start names the missing shm.group"

# 5
sim_yaml piped
rc=(0 0)
timeout 60 "$daemon" -c "$tmp/piped.yaml" 2>&1 | head -1 >"$tmp/piped.first"
rc=("${PIPESTATUS[@]}")
[ "${rc[0]}" = 0 ] || fail "ds1928d | head -1: daemon exit ${rc[0]} (141: killed by SIGPIPE, 124: never stopped)"
[ -s "$tmp/piped.first" ] || fail "ds1928d | head -1: no line"
[ ! -e "/dev/shm${shm}" ] || fail "ds1928d | head -1 left the shared memory $shm behind"
[ ! -e "$tmp/control.sock" ] || fail "ds1928d | head -1 left the control socket behind"
pass "ds1928d | head -1: clean stop on SIGPIPE (exit 0, shm and socket removed)"
