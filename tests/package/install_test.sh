#!/bin/bash
# The Debian packages in a fresh Debian 12 root: install, then check what an administrator gets.
#
#   1. a minimal bookworm root made by mmdebstrap from Debian's mirror, with systemd and the
#      packages' dependencies (resolved by apt from the .deb's Depends), cached as a tarball in
#      DEB_DIR keyed by that package list — reruns only unpack it;
#   2. dpkg installs ds1928d, libds1928-dev, python3-ds1928 (and linuxcnc-ds1928 when built) there; the maintainer scripts run (systemd-sysusers
#      creates the user and groups; systemd is not running in the root, so nothing is started);
#   3. files: programs, units, sysusers/tmpfiles/udev entries, man pages, header and example,
#      the configuration as a conffile;
#   4. the system user ds1928d (group ds1928, no login) and the groups ds1928, ds1928-admin;
#   5. the units: systemd-analyze verify; the exposure score of ds1928d.service ≤ 2.0;
#   6. the configuration passes ds1928d --check-config;
#   7. the installed daemon starts in the root as ds1928d with the unit's capabilities (READY=1),
#      runs real-time, and a member of ds1928 gets its status and positions;
#   8. that member reads axis 0 with `python3 -c 'import ds1928 ...'`, and LinuxCNC's halcmd loads
#      the HAL component ds1928 (as that member, RTAPI_UID) with axis 0 valid;
#   9. the shipped metrics drop-in (/usr/share/ds1928d/ds1928d-metrics.conf) enabled as
#      docs/operations.md says: the unit still verifies clean with it, and GET /metrics of the
#      installed daemon answers with the cycle counter (the address from `status`).
# Everything runs in a private mount namespace; the root is removed at the end.
#
# Usage: install_test.sh DEB_DIR        (root; needs mmdebstrap, network to the Debian mirror
#                                        only on the first run)
set -u
debs=$(cd "${1:?directory with the .deb files}" && pwd)
here=$(cd "$(dirname "$0")" && pwd)
deploy=$here/../deploy

if [ "$(id -u)" != 0 ]; then
  echo "SKIP: needs root (chroot, mounts)"
  exit 77
fi
if [ -z "${INSTALL_TEST_NS:-}" ]; then
  export INSTALL_TEST_NS=1
  exec unshare --mount --propagation private -- "$0" "$@"
fi

start=$(date +%s)
daemon_deb=$(ls "$debs"/ds1928d_*.deb 2>/dev/null | head -1)
dev_deb=$(ls "$debs"/libds1928-dev_*.deb 2>/dev/null | head -1)
py_deb=$(ls "$debs"/python3-ds1928_*.deb 2>/dev/null | head -1)
# linuxcnc-ds1928 exists when the packages were built with linuxcnc-uspace-dev installed.
hal_deb=$(ls "$debs"/linuxcnc-ds1928_*.deb 2>/dev/null | head -1)
[ -n "$daemon_deb" ] && [ -n "$dev_deb" ] && [ -n "$py_deb" ] ||
  { echo "FAIL: no ds1928d/libds1928-dev/python3-ds1928 .deb in $debs"; exit 1; }
[ -n "$hal_deb" ] || echo "note: no linuxcnc-ds1928 .deb (built without linuxcnc-uspace-dev): not checked"
all_debs=("$daemon_deb" "$dev_deb" "$py_deb" ${hal_deb:+"$hal_deb"})

# --- 1. the base root -------------------------------------------------------------------------
# Depends of both packages, without versions and alternatives beyond the first.
deps=$( for d in "${all_debs[@]}"; do dpkg-deb -f "$d" Depends; echo ,; done |
        tr ',' '\n' | sed -e 's/|.*//' -e 's/(.*)//' -e 's/ //g' | grep -v '^$' | sort -u | tr '\n' ',')
include="systemd,util-linux,passwd,python3-minimal,${deps%,}"
key=$(printf '%s' "bookworm $include" | sha256sum | cut -c1-12)
cache=$debs/pkgtest-bookworm-$key.tar
if [ -f "$cache" ]; then
  echo "base root: cached $cache"
else
  echo "base root: mmdebstrap bookworm (minbase + $include)"
  rm -rf "$debs"/pkgtest-bookworm-*.tar "$debs"/pkgtest-bookworm-*.tar.part
  # --format: mmdebstrap picks the format from the name's ending, and "*.part" is no tarball.
  mmdebstrap --variant=minbase --format=tar --include="$include" bookworm "$cache.part" \
    || { echo "FAIL: mmdebstrap"; exit 1; }
  mv "$cache.part" "$cache"
fi
root=$(mktemp -d /var/tmp/ds1928d-pkgtest.XXXXXX)
cleanup() {
  [ -n "${pid:-}" ] && kill -TERM "$pid" 2>/dev/null && timeout 20 tail --pid="$pid" -f /dev/null
  for m in "$root/dev/shm" "$root/dev" "$root/proc" "$root/run"; do
    mountpoint -q "$m" && umount -l "$m"
  done
  rm -rf "$root"
}
trap cleanup EXIT
tar -C "$root" -xf "$cache"
mount -t proc proc "$root/proc"
mount --rbind /dev "$root/dev"
mount -t tmpfs -o mode=1777 tmpfs "$root/dev/shm"   # its own /dev/shm: no clash with the host
mount -t tmpfs -o mode=0755 tmpfs "$root/run"
unpacked=$(( $(date +%s) - start ))

fail=0
check() {  # check DESCRIPTION COMMAND...
  if "${@:2}"; then echo "ok:   $1"; else echo "FAIL: $1"; fail=1; fi
}
in_root() { chroot "$root" "$@"; }

# --- 2. install ---------------------------------------------------------------------------------
cp "${all_debs[@]}" "$root/tmp/"
# As an administrator installs them: apt resolves what the cached root lacks (then it needs the
# mirror's package lists).
apt_install() {
  in_root env DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends \
    $(for d in "${all_debs[@]}"; do echo "/tmp/${d##*/}"; done)
}
if ! apt_install; then
  in_root apt-get update -qq && apt_install || { echo "FAIL: apt-get install"; exit 1; }
fi
check "the packages installed" \
  test "$(in_root dpkg-query -W -f='${db:Status-Status} ' ds1928d libds1928-dev python3-ds1928)" = "installed installed installed "
[ -n "$hal_deb" ] && check "linuxcnc-ds1928 installed" \
  test "$(in_root dpkg-query -W -f='${db:Status-Status}' linuxcnc-ds1928)" = "installed"
check "file /usr/lib/python3/dist-packages/ds1928/shm.py" \
  test -f "$root/usr/lib/python3/dist-packages/ds1928/shm.py"
[ -n "$hal_deb" ] && check "file /usr/lib/linuxcnc/modules/ds1928.so" \
  test -f "$root/usr/lib/linuxcnc/modules/ds1928.so"

# --- 3. files -----------------------------------------------------------------------------------
for f in /usr/bin/ds1928d /usr/bin/ds1928ctl /usr/bin/ds1928-sim \
         /lib/systemd/system/ds1928d.service /lib/systemd/system/ds1928d@.service \
         /usr/lib/sysusers.d/ds1928d.conf /usr/lib/tmpfiles.d/ds1928d.conf \
         /lib/udev/rules.d/60-ds1928d.rules \
         /usr/share/man/man8/ds1928d.8.gz /usr/share/man/man1/ds1928ctl.1.gz \
         /usr/share/man/man1/ds1928-sim.1.gz /etc/ds1928d/ds1928d.yaml \
         /usr/share/doc/ds1928d/copyright /usr/share/doc/ds1928d/README.md.gz \
         /usr/include/ds1928/shm.h /usr/include/ds1928/shm.hpp \
         /usr/share/doc/libds1928-dev/examples/shm_reader.c; do
  check "file $f" test -s "$root$f"
done
check "/etc/ds1928d/ds1928d.yaml is a conffile" \
  grep -q '/etc/ds1928d/ds1928d.yaml' <<<"$(in_root dpkg-query -W -f='${Conffiles}' ds1928d)"
check "man ds1928d(8) has the option --shm-name" \
  sh -c "zcat '$root/usr/share/man/man8/ds1928d.8.gz' | grep -q 'shm\\\\-name'"

# --- 4. user and groups -------------------------------------------------------------------------
pw=$(in_root getent passwd ds1928d)
echo "  passwd: $pw"
check "group ds1928 exists" in_root getent group ds1928
check "group ds1928-admin exists" in_root getent group ds1928-admin
check "user ds1928d exists, a system user" test -n "$pw" -a "$(cut -d: -f3 <<<"$pw")" -lt 1000
check "user ds1928d's group is ds1928" \
  test "$(cut -d: -f4 <<<"$pw")" = "$(in_root getent group ds1928 | cut -d: -f3)"
check "user ds1928d cannot log in" test "$(cut -d: -f7 <<<"$pw")" = /usr/sbin/nologin

# --- 5. units -----------------------------------------------------------------------------------
for u in ds1928d.service ds1928d@bus1.service; do
  out=$(in_root systemd-analyze verify --man=no "$u" 2>&1)
  [ -n "$out" ] && sed 's/^/  | /' <<<"$out"
  check "systemd-analyze verify $u: clean" test -z "$out"
done
score=$(in_root systemd-analyze security --offline=true /lib/systemd/system/ds1928d.service 2>&1 |
        sed -n 's/.*Overall exposure level for .*: \([0-9.]*\).*/\1/p')
echo "  exposure level of the installed ds1928d.service: $score"
check "exposure level ≤ 2.0" awk -v s="${score:-99}" 'BEGIN {exit !(s <= 2.0)}'

# --- 6. configuration ---------------------------------------------------------------------------
out=$(in_root ds1928d --check-config /etc/ds1928d/ds1928d.yaml 2>&1)
echo "  $out"
check "the packaged configuration is valid" grep -q ': ok (bus simulated' <<<"$out"

# --- 7. the daemon starts as the service would start it ----------------------------------------
# RuntimeDirectory=ds1928d: /run/ds1928d owned by the service user.
install -d -m 0755 -o "$(cut -d: -f3 <<<"$pw")" -g "$(cut -d: -f4 <<<"$pw")" "$root/run/ds1928d"
in_root useradd --no-create-home --shell /usr/sbin/nologin --groups ds1928 reader
caps=-all,+net_raw,+sys_nice,+ipc_lock
pid=$(NOTIFY_START_ROOT=$root python3 "$deploy/notify_start.py" "$root/run/ds1928d" 60 \
        "$root/tmp/daemon.log" -- chroot "$root" setpriv --reuid=ds1928d --regid=ds1928 \
        --init-groups --inh-caps=$caps --ambient-caps=$caps --bounding-set=$caps \
        --no-new-privs -- /usr/bin/ds1928d --config /etc/ds1928d/ds1928d.yaml)
check "the installed daemon starts as ds1928d (READY=1)" test -n "$pid"
if [ -n "$pid" ]; then
  sed 's/^/  | /' "$root/tmp/daemon.log"
  status=$(in_root setpriv --reuid=reader --regid=reader --init-groups -- ds1928ctl --json status)
  check "a member of ds1928 gets the status, real-time" grep -q '"realtime":true' <<<"$status"
  position=$(in_root setpriv --reuid=reader --regid=reader --init-groups -- \
               ds1928ctl --json position --axis 0)
  check "a member of ds1928 reads the shared memory" grep -q '"cycle":' <<<"$position"
  check "the shared memory belongs to ds1928d:ds1928" \
    test "$(stat -c '%u:%g %a' "$root/dev/shm/ds1928d" 2>/dev/null)" = "$(cut -d: -f3 <<<"$pw"):$(cut -d: -f4 <<<"$pw") 640"
  # --- 8. python3-ds1928 and linuxcnc-ds1928 against the installed daemon ----------------------
  py=$(in_root setpriv --reuid=reader --regid=reader --init-groups -- \
         python3 -c 'import ds1928; print(ds1928.Reader("/ds1928d").axis(0))' 2>&1)
  echo "  python3: ${py:0:160}"
  check "python3 -c 'import ds1928' reads axis 0 (member of ds1928)" grep -q "state='valid'" <<<"$py"
  if [ -n "$hal_deb" ]; then
    # LinuxCNC's realtime in its own IPC and PID namespaces (one per machine otherwise), started
    # by the reader as a LinuxCNC user would (rtapi_app is setuid root and reads files as the
    # user, with the user's groups); its socket in a directory the reader owns.
    in_root install -d -o reader /tmp/rtapi
    hal=$(chroot "$root" unshare --ipc --pid --fork --mount-proc --propagation unchanged \
            setpriv --reuid=reader \
            --regid=reader --init-groups env RTAPI_FIFO_PATH=/tmp/rtapi/fifo \
            sh -c '/usr/lib/linuxcnc/realtime start &&
              halcmd loadrt ds1928 && halcmd loadrt threads name1=servo period1=1000000 &&
              halcmd addf ds1928.read servo && halcmd start && sleep 0.5 &&
              halcmd show pin ds1928; halcmd stop; halcmd unload all; /usr/lib/linuxcnc/realtime stop' 2>&1)
    sed 's/^/  | /' <<<"$hal"
    check "halcmd loadrt ds1928 in the root: axis 0 valid" \
      grep -Eq 'bit +OUT +TRUE +ds1928\.0\.valid' <<<"$hal"
  fi
  # --- 9. the metrics drop-in, and a scrape ------------------------------------------------------
  check "the metrics drop-in is shipped" test -f "$root/usr/share/ds1928d/ds1928d-metrics.conf"
  in_root install -D -m 0644 /usr/share/ds1928d/ds1928d-metrics.conf \
    /etc/systemd/system/ds1928d.service.d/metrics.conf
  out=$(in_root systemd-analyze verify --man=no ds1928d.service 2>&1)
  [ -n "$out" ] && sed 's/^/  | /' <<<"$out"
  check "systemd-analyze verify ds1928d.service with the metrics drop-in: clean" test -z "$out"
  check "the enabled drop-in allows AF_INET" \
    grep -q '^RestrictAddressFamilies=.*AF_INET' "$root/etc/systemd/system/ds1928d.service.d/metrics.conf"
  # The root shares the host's network: the daemon's endpoint is reached from here.
  address=$(python3 -c 'import json,sys; print(json.load(sys.stdin)["daemon"]["metrics"])' <<<"$status" 2>/dev/null)
  echo "  metrics endpoint: ${address:-?}"
  scrape=$(python3 -c 'import sys, urllib.request
print(urllib.request.urlopen("http://" + sys.argv[1] + "/metrics", timeout=5).read().decode())' "$address" 2>&1)
  check "GET /metrics of the installed daemon: ds1928_cycles_total and the axis state" \
    grep -q '^ds1928_cycles_total [1-9]' <<<"$scrape"
  check "GET /metrics: axis 0 valid" grep -q '^ds1928_axis_state{axis="0",name="axis0",state="valid"} 1' <<<"$scrape"
fi

elapsed=$(( $(date +%s) - start ))
echo "time: ${elapsed} s in all (root ready after ${unpacked} s)"
[ "$fail" = 0 ] && echo "PASS: the packages install into a fresh Debian 12 root and the daemon starts there"
exit "$fail"
