#!/bin/bash
# Runs inside the CAN test guest, chrooted into the host's root: brings up the two emulated
# SJA1000 controllers (can0, can1: one emulated bus) and a vcan0, waits until all three are UP,
# then runs the test script with its arguments and exits with its status.
#
# Usage: guest-main.sh SCRIPT [ARGS...]
# Environment for the script: CANIO_BITRATE, CANIO_RESTART_MS, CANIO_WORK (writable, kept on the host).
set -u
export PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin
export CANIO_BITRATE=${CANIO_BITRATE:-500000}
export CANIO_RESTART_MS=${CANIO_RESTART_MS:-100}
script=${1:?test script}
shift
# iproute2 by its path: busybox's applets may come first and its ip knows no "type can".
ip=/usr/sbin/ip

fail() { echo "guest-main: FAIL: $*"; exit 1; }

for dev in can0 can1; do
  [ -e /sys/class/net/$dev ] || fail "$dev missing: kvaser_pci did not register two SJA1000 channels"
done
# One ip process for all of it (a process start costs much under TCG). Two commands per CAN link:
# after "type can" every word is a CAN option, so "up" cannot follow it.
$ip -batch - << EOF || fail "ip -batch could not configure can0/can1 ($CANIO_BITRATE bit/s, restart-ms $CANIO_RESTART_MS) and vcan0"
link set can0 type can bitrate $CANIO_BITRATE restart-ms $CANIO_RESTART_MS
link set can0 up
link set can1 type can bitrate $CANIO_BITRATE restart-ms $CANIO_RESTART_MS
link set can1 up
link add vcan0 type vcan
link set vcan0 up
EOF

# A link may still report NO-CARRIER right after "up": wait (bounded) until all three are UP with
# carrier. Read from sysfs with the shell's own read: every process start is expensive under TCG.
links_up() {
  local dev flags carrier
  for dev in can0 can1 vcan0; do
    read -r flags < /sys/class/net/$dev/flags || return 1
    (((flags & 1) == 1)) || return 1
    read -r carrier 2> /dev/null < /sys/class/net/$dev/carrier || return 1
    [ "$carrier" = 1 ] || return 1
  done
  return 0
}
for ((i = 0; i < 200; i++)); do
  links_up && break
  sleep 0.05
done
links_up || { $ip -details link show; fail "links not UP after 10 s"; }

read -r up _ < /proc/uptime
echo "guest-main: kernel $(< /proc/sys/kernel/osrelease), can0/can1 at $CANIO_BITRATE bit/s restart-ms $CANIO_RESTART_MS, vcan0 up (guest uptime $up s)"
echo "guest-main: running $script $*"
read -r start _ < /proc/uptime
"$script" "$@"
rc=$?
read -r end _ < /proc/uptime
echo "guest-main: $script exited $rc after $(awk -v a="$start" -v b="$end" 'BEGIN{printf "%.1f", b-a}') s (guest clock)"
exit $rc
