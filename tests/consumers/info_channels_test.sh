#!/bin/bash
# The additional-information channels from the simulated encoder to every reader: the daemon on
# the simulated node with axes[0].info (temperature1 and temperature2 by name), its encoder at
# 55.3 °C and -5.0 °C (encoder_file). EnDat 2.2 temperatures are 0.1 K words (raw = (°C + 273.2)
# × 10): 3285 and 2682. The same values, valid and freshly read, in
#   1. ds1928ctl --json position (and the text line),
#   2. the Python reader (ds1928.Reader(...).axis(0).info),
#   3. the HAL component's pins ds1928.x.info-<name>, -valid, -age-us (real LinuxCNC, halcmd),
#   4. the OpenMetrics endpoint (ds1928_axis_info_value / _valid).
#
# Usage: info_channels_test.sh BUILD_DIR SOURCE_DIR     (root; 77 = skipped)
set -u
build=${1:?build dir}
src=${2:?source dir}
module=$build/linuxcnc/ds1928.so
if [ "$(id -u)" != 0 ]; then echo "SKIP: needs root (namespaces, SCHED_FIFO)"; exit 77; fi
for t in halcmd unshare python3 curl; do
  command -v $t >/dev/null || { echo "SKIP: $t missing (make deps-test installs it)"; exit 77; }
done
[ -f "$module" ] || { echo "FAIL: $module not built (linuxcnc-uspace-dev installed?)"; exit 1; }

. "$src/tests/lib/linuxcnc.sh"
linuxcnc_enter_namespaces "$0" "$@"

linuxcnc_test_begin info

linuxcnc_setup "$work" "$module" || { echo "FAIL: cannot overlay LinuxCNC's modules"; exit 1; }
ds1928_daemon_configure "$work" "$shm" 1000 || exit 1
printf 'endat: "2.2"\ntemperature_c: 55.3\ntemperature2_c: -5.0\n' >"$work/encoder.yaml"
port=$((20000 + RANDOM % 20000))
python3 - "$work/daemon.yaml" "$work/encoder.yaml" "$port" <<'PY' || exit 1
import sys
path, encoder, port = sys.argv[1:4]
text = open(path).read()
for old, new in [
    ('      encoder_file: ""', f'      encoder_file: "{encoder}"'),
    ("    module:                     # X20DS1928",
     "    info:\n      - temperature1\n      - {name: motor_temp, info: temperature2}\n"
     "    module:                     # X20DS1928"),
    ("  listen: 127.0.0.1:9928 ", f"  listen: 127.0.0.1:{port} ")]:
    if old not in text:
        sys.exit(f"FAIL: no '{old}' in config/simulated.yaml")
    text = text.replace(old, new, 1)
open(path, "w").write(text)
PY
ds1928_daemon_start "$build" "$src" "$work" || exit 1

echo "--- 1. ds1928ctl position"
# The channels follow the encoder's EnDat cycles: wait until both were read valid.
for _ in $(seq 100); do
  "$ctl" --shm "$shm" --json position --axis 0 >"$work/ctl.json" 2>&1
  python3 -c 'import json,sys; d=json.load(open(sys.argv[1])); sys.exit(0 if all(c["valid"] for c in d["info"]) and len(d["info"]) == 2 else 1)' "$work/ctl.json" && break
  sleep 0.05
done
cat "$work/ctl.json"
check_ctl() {
  python3 - "$work/ctl.json" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
want = [(1, "temperature1", 3285), (2, "motor_temp", 2682)]
got = [(c["channel"], c["name"], c["value"]) for c in d["info"]]
ok = got == want and all(c["valid"] and c["age_us"] is not None and c["age_us"] < 1_000_000
                         for c in d["info"])
print(f"      ctl: {got}")
sys.exit(0 if ok else 1)
PY
}
check "ctl --json: both channels, the encoder's values, valid, read within 1 s" check_ctl
"$ctl" --shm "$shm" position --axis 0 >"$work/ctl.txt"
cat "$work/ctl.txt"
check "ctl text: the info line names both channels with their values" \
  grep -q "info temperature1=3285 motor_temp=2682" "$work/ctl.txt"

echo "--- 2. Python reader"
check_python() {
  PYTHONPATH=$src/python python3 - "$shm" <<'PY'
import sys
from ds1928 import shm
with shm.Reader(sys.argv[1]) as r:
    assert r.has_info
    info = r.axis(0).info
    got = [(c.channel, c.name, c.value, c.valid) for c in info]
    print(f"      python: {got}")
    sys.exit(0 if got == [(1, "temperature1", 3285, True), (2, "motor_temp", 2682, True)]
             and all(c.age_us is not None for c in info) else 1)
PY
}
check "Python: the same channels, values and validity" check_python

echo "--- 3. HAL pins"
linuxcnc_start >"$work/rt.log" 2>&1 || { cat "$work/rt.log"; exit 1; }
halcmd loadrt ds1928 shm="$shm" axes=x || { echo "FAIL: loadrt ds1928"; exit 1; }
halcmd loadrt threads name1=servo period1=1000000 || exit 1
halcmd addf ds1928.read servo && halcmd start || exit 1
check "HAL: x.info-temperature1-valid" hal_wait_pin ds1928.x.info-temperature1-valid TRUE 10
check "HAL: x.info-temperature1 = 3285" test "$(hal_getp ds1928.x.info-temperature1)" = 3285
check "HAL: x.info-motor_temp = 2682" test "$(hal_getp ds1928.x.info-motor_temp)" = 2682
check "HAL: x.info-motor_temp-valid" test "$(hal_getp ds1928.x.info-motor_temp-valid)" = TRUE
age=$(hal_getp ds1928.x.info-temperature1-age-us)
check "HAL: x.info-temperature1-age-us within a second ($age)" \
  python3 -c "import sys; sys.exit(0 if 0 <= float('$age') < 1e6 else 1)"
halcmd show pin ds1928.x.info >"$work/pins.txt"; cat "$work/pins.txt"
halcmd stop; halcmd unload all

echo "--- 4. OpenMetrics"
curl -sf "http://127.0.0.1:$port/metrics" >"$work/metrics.txt" || echo "      (no metrics on $port)"
check "metrics: ds1928_axis_info_value of temperature1 = 3285" \
  grep -qE '^ds1928_axis_info_value\{.*info="temperature1"\} 3285(\.0)?$' "$work/metrics.txt"
check "metrics: ds1928_axis_info_valid of motor_temp = 1" \
  grep -qE '^ds1928_axis_info_valid\{.*info="motor_temp"\} 1$' "$work/metrics.txt"
grep '^ds1928_axis_info' "$work/metrics.txt"
exit $fail
