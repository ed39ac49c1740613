#!/bin/bash
# The hardened unit still runs a real-time cycle: ds1928d under the settings of
# systemd/ds1928d.service (an unprivileged uid, only CAP_NET_RAW/CAP_SYS_NICE/CAP_IPC_LOCK as
# ambient capabilities, no new privileges, read-only file system but its runtime directory,
# private /tmp, no /home) must
#   1. come up (READY=1 over the notification socket, as systemd waits for it),
#   2. run its cycle thread "ds1928-cycle" at SCHED_FIFO with the configured priority,
#   3. have its memory locked (VmLck ≈ VmRSS) and report "realtime": true,
#   4. publish in shared memory (the publication's cycle advances) and answer on its socket,
#   5. hold exactly the three capabilities, NoNewPrivs, the service uid, and see / read-only.
# Where systemd is PID 1 the unit itself could be started with systemd-run; CI hosts and this
# test do not assume it: the settings are applied by hand by as_service.sh (which says which).
#
# Usage: hardened_rt_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
build=${1:?build dir}
src=${2:?source dir}
here=$(cd "$(dirname "$0")" && pwd)
. "$here/stage.sh"

if [ "$(id -u)" != 0 ]; then
  echo "SKIP: needs root (setpriv to the service uid, mount namespace); run ctest as root"
  exit 77
fi

# A uid/gid of nobody on this machine stands for the system user ds1928d.
svc_id=$((61000 + $$ % 4000))
while getent passwd "$svc_id" >/dev/null || getent group "$svc_id" >/dev/null; do
  svc_id=$((svc_id + 1))
done
run=/run/ds1928d-rt-$$          # RuntimeDirectory=
shm=/ds1928d-rt-$$
pid=""
fail=0
cleanup() {
  if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
    kill -TERM "$pid"
    timeout 20 tail --pid="$pid" -f /dev/null || kill -KILL "$pid"
  fi
  rm -rf "$run"
  rm -f "/dev/shm$shm" "/dev/shm$shm.wait"
}
trap 'cleanup; unstage_programs' EXIT
stage_programs "$build/daemon/ds1928d" "$build/tools/ds1928ctl/ds1928ctl" ||
  { echo "FAIL: cannot stage the programs under /var/lib/ds1928d-test"; exit 1; }
daemon=${staged[ds1928d]} ctl=${staged[ds1928ctl]}
check() {  # check DESCRIPTION COMMAND...
  if "${@:2}"; then echo "ok:   $1"; else echo "FAIL: $1"; fail=1; fi
}

mkdir -m 0755 "$run"
chown "$svc_id:$svc_id" "$run"
sed -e "s|^\(  name:\) /ds1928d |\1 $shm |" \
    -e "s|^\(  path:\) /run/ds1928d/control.sock|\1 $run/control.sock|" \
    -e "s|^\(  hold_cpu_dma_latency:\) true|\1 false|" \
    "$src/config/simulated.yaml" > "$run/ds1928d.yaml"
grep -q "name: $shm " "$run/ds1928d.yaml" && grep -q "path: $run/control.sock" "$run/ds1928d.yaml" ||
  { echo "FAIL: could not derive the test configuration"; exit 1; }
chmod 0644 "$run/ds1928d.yaml"

pid=$(python3 "$here/notify_start.py" "$run" 60 "$run/daemon.log" -- \
        "$here/as_service.sh" --user "$svc_id" --group "$svc_id" --rw "$run" -- \
        "$daemon" --config "$run/ds1928d.yaml")
if [ -z "$pid" ]; then echo "FAIL: the daemon did not come up under the hardened settings"; exit 1; fi
echo "ds1928d pid $pid under uid $svc_id; its log:"
sed 's/^/  | /' "$run/daemon.log"

status=/proc/$pid/status
field() { awk -v k="$1:" '$1 == k {print $2}' "$status"; }
check "runs as the service uid" test "$(field Uid)" = "$svc_id"
check "effective capabilities are exactly net_raw, sys_nice, ipc_lock (0x806000)" \
  test "$(field CapEff)" = 0000000000806000
check "bounding set is the same three" test "$(field CapBnd)" = 0000000000806000
check "no new privileges" test "$(field NoNewPrivs)" = 1
check "sees / read-only (ProtectSystem=strict)" \
  awk '$5 == "/" && $6 ~ /(^|,)ro(,|$)/ {found=1} END {exit !found}' "/proc/$pid/mountinfo"

cycle_tid=""
for t in /proc/"$pid"/task/*; do
  [ "$(cat "$t/comm")" = ds1928-cycle ] && cycle_tid=${t##*/}
done
check "the cycle thread ds1928-cycle exists" test -n "$cycle_tid"
if [ -n "$cycle_tid" ]; then
  policy=$(chrt -p "$cycle_tid")
  echo "  chrt -p $cycle_tid: $(echo "$policy" | tr '\n' ';')"
  check "the cycle thread is SCHED_FIFO" grep -q "SCHED_FIFO" <<<"$policy"
  check "at the configured priority 80" grep -q "priority: 80" <<<"$policy"
  check "/proc/PID/sched says policy 1 (SCHED_FIFO)" \
    awk '$1 == "policy" {found = ($3 == 1)} END {exit !found}' "/proc/$pid/task/$cycle_tid/sched"
fi
lck=$(field VmLck) rss=$(field VmRSS)
echo "  VmLck $lck kB, VmRSS $rss kB"
# The sanitizer runtimes intercept mlockall and report success without locking anything (their
# shadow memory could not be locked): VmLck says nothing in such a build.
if ldd "$daemon" 2>/dev/null | grep -qE 'lib(a|t)san'; then
  echo "  NOTE: sanitizer build: mlockall is faked by the runtime, VmLck not checked"
else
  check "memory is locked (VmLck > 0 and ≥ 90 % of VmRSS)" \
    test "${lck:-0}" -gt 0 -a $((${lck:-0} * 10)) -ge $((${rss:-1} * 9))
fi

reply=$("$ctl" --socket "$run/control.sock" --json status)
echo "  status: $(cut -c1-300 <<<"$reply")"
check "status says realtime" grep -q '"realtime":true' <<<"$reply"
check "status says memory locked" grep -q 'memory locked' <<<"$reply"
first=$("$ctl" --shm "$shm" --json position --axis 0 | grep -o '"cycle":[0-9]*' | head -1)
second=$("$ctl" --shm "$shm" --json position --follow --count 3 --axis 0 |
           grep -o '"cycle":[0-9]*' | tail -1)
echo "  shm publication cycle: ${first#*:} then ${second#*:}"
check "publishes in shared memory (cycle advances)" \
  test -n "$first" -a -n "$second" -a "${second#*:}" -gt "${first#*:}"

[ "$fail" = 0 ] && echo "PASS: SCHED_FIFO and mlockall under the hardened service settings"
exit "$fail"
