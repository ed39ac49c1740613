# LinuxCNC's realtime environment for a test or bench (sourced). The environment is one per
# machine (SysV shared memory key, `ps -C rtapi_app`), and rtapi_app loads modules by name from
# its module directory only; so a user of this file runs in its own mount, IPC and PID
# namespaces, with the module directory overlaid by one that adds a freshly built module.
#
#   linuxcnc_enter_namespaces "$0" "$@"   re-executes the script in new namespaces (once)
#   linuxcnc_setup WORK MODULE.so          overlay + RTAPI_UID (nobody) + RTAPI_FIFO_PATH
#   linuxcnc_start / linuxcnc_stop         the realtime environment (rtapi_app)
#   hal_getp PIN / hal_wait_pin PIN VALUE SECONDS

linuxcnc_enter_namespaces() {
  if [ -z "${DS1928_HAL_IN_NS:-}" ]; then
    exec unshare --mount --ipc --pid --fork --mount-proc --propagation private \
      env DS1928_HAL_IN_NS=1 "$@"
  fi
}

LINUXCNC_MODULES=/usr/lib/linuxcnc/modules
LINUXCNC_REALTIME=/usr/lib/linuxcnc/realtime

linuxcnc_setup() {  # WORK MODULE
  local work=$1 module=$2 f
  mkdir -p "$work/orig" "$work/modules" "$work/fifo" || return 1
  chmod 0755 "$work"
  mount --bind "$LINUXCNC_MODULES" "$work/orig" || return 1
  for f in "$work"/orig/*; do ln -s "$f" "$work/modules/"; done
  cp "$module" "$work/modules/" || return 1
  mount --bind "$work/modules" "$LINUXCNC_MODULES" || return 1
  # rtapi_app runs as RTAPI_UID when started by root; its socket goes to RTAPI_FIFO_PATH.
  chown nobody "$work/fifo"
  export RTAPI_UID=$(id -u nobody) RTAPI_FIFO_PATH=$work/fifo/rtapi HAL_RTMOD_DIR=$LINUXCNC_MODULES
}

linuxcnc_start() { "$LINUXCNC_REALTIME" start; }
linuxcnc_stop() {
  halcmd stop >/dev/null 2>&1
  halcmd unload all >/dev/null 2>&1
  "$LINUXCNC_REALTIME" stop >/dev/null 2>&1
}

hal_getp() { halcmd -s getp "$1" 2>/dev/null | tr -d ' '; }
hal_wait_pin() {  # PIN VALUE SECONDS: until the pin shows VALUE
  local end=$((SECONDS + $3))
  while [ $SECONDS -lt $end ]; do [ "$(hal_getp "$1")" = "$2" ] && return 0; sleep 0.05; done
  echo "      $1 = $(hal_getp "$1") after $3 s, expected $2"
  return 1
}

# The daemon on the simulated node with unique names (ds1928_daemon_configure WORK SHM PERIOD_US;
# ds1928_daemon_start BUILD SRC WORK sets $dpid; ds1928_daemon_stop SIGNAL).
ds1928_daemon_configure() {
  sed -e "s|^\(  name:\) /ds1928d |\1 $2 |" \
      -e "s|^\(  path:\) /run/ds1928d/control.sock|\1 $1/control.sock|" \
      -e "s|^\(  period_us:\) 1000 |\1 $3 |" \
      -e "s|^\(  hold_cpu_dma_latency:\) true|\1 false|" \
      "$src/config/simulated.yaml" > "$1/daemon.yaml"
  grep -q "name: $2 " "$1/daemon.yaml" && grep -q "period_us: $3 " "$1/daemon.yaml" ||
    { echo "FAIL: could not derive the daemon's configuration"; return 1; }
}
ds1928_daemon_start() {  # BUILD SRC WORK
  dpid=$(python3 "$2/tests/deploy/notify_start.py" "$3" 60 "$3/daemon.log" -- \
           "$1/daemon/ds1928d" --config "$3/daemon.yaml")
  [ -n "$dpid" ] || { echo "FAIL: the daemon did not start"; cat "$3/daemon.log"; return 1; }
}
ds1928_daemon_stop() {  # SIGNAL
  [ -n "${dpid:-}" ] || return 0
  kill -"$1" "$dpid" 2>/dev/null
  timeout 20 tail --pid="$dpid" -f /dev/null
  dpid=""
}

# Undoes linuxcnc_setup. WORK/orig is LinuxCNC's real module directory until unmounted: the
# caller removes WORK only when this succeeded.
linuxcnc_teardown() {  # WORK
  local work=$1
  mountpoint -q "$LINUXCNC_MODULES" && umount "$LINUXCNC_MODULES"
  mountpoint -q "$work/orig" && umount "$work/orig"
  ! mountpoint -q "$work/orig"
}

# The common start of a consumer test, once in its namespaces: a tag, a private work directory,
# the shared-memory name /ds1928-KIND-TAG, ds1928ctl, `check`, and at exit the cleanup that stops
# LinuxCNC and the daemon and removes what the run made. Needs $build (and $module for setup).
linuxcnc_test_begin() {  # KIND
  tag=$(printf '%x%x' $$ $((RANDOM % 256)))$(date +%N | cut -c1-4)
  work=$(mktemp -d "/tmp/ds1928-$1-XXXXXX")
  chmod 0755 "$work"
  shm=/ds1928-$1-$tag
  ctl=$build/tools/ds1928ctl/ds1928ctl
  dpid=""
  fail=0
  trap linuxcnc_test_cleanup EXIT
}
linuxcnc_test_cleanup() {
  linuxcnc_stop
  ds1928_daemon_stop TERM
  rm -f /dev/shm"$shm" /dev/shm"$shm".wait
  linuxcnc_teardown "$work" && rm -rf "$work"
}
check() {  # check DESCRIPTION COMMAND...
  if "${@:2}"; then echo "ok:   $1"; else echo "FAIL: $1"; fail=1; fi
}
