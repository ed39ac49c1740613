#!/bin/bash
# Guest script for run-guest.sh: the port layer's SocketCAN test program on the real kernel CAN
# stack. In the guest AF_CAN, can0 + can1 (one emulated bus) and vcan exist, so the program must
# run every test case, the controller-pair ones included: its "skipped" (77) is a failure here.
# Usage: guest_socketcan_port.sh PATH/TO/canio_socketcan_test
set -u
test_bin=${1:?canio_socketcan_test path}
[ -x "$test_bin" ] || { echo "FAIL: $test_bin not built"; exit 1; }
out=$(mktemp)
trap 'rm -f "$out"' EXIT
DS1928_CAN_IFACES="can0 can1" "$test_bin" 2>&1 | tee "$out"
rc=${PIPESTATUS[0]}
if [ "$rc" = 77 ]; then
  echo "FAIL: canio_socketcan_test skipped inside the guest, where AF_CAN and can0/can1 exist"
  exit 1
fi
[ "$rc" = 0 ] || { echo "FAIL: canio_socketcan_test exited $rc"; exit 1; }
if ! grep -q "controller pair: can0 + can1" "$out"; then
  echo "FAIL: canio_socketcan_test did not use the can0 + can1 controller pair"
  exit 1
fi
echo "ok: canio_socketcan_test passed on $(uname -r) with the can0 + can1 pair"
