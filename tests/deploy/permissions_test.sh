#!/bin/bash
# The permission model with real uids, as the package sets it up: the daemon runs as its own
# user whose group is the readers' group, under the unit's settings (as_service.sh); the shared
# memory is 0640 and the socket 0660, both of the readers' group; the admin group may change the
# encoder. Throwaway users and groups with unique names stand for ds1928d, ds1928, ds1928-admin.
#
#   1. a reader (member of the readers' group) maps the shared memory and gets `status`, but gets
#      permission_denied for ack-errors, endat-ack, endat write-param, endat-reset;
#   2. an admin (readers + admin group) may acknowledge;
#   3. a uid outside both groups can neither connect to the socket nor map the shared memory;
#   4. a planted symbolic link or another user's file at the shared-memory name, and a planted
#      link, another user's socket, another user's directory or a symlinked directory at the
#      socket path: the daemon refuses to start with a message saying so, and follows, removes or
#      adopts nothing.
#
# Usage: permissions_test.sh BUILD_DIR SOURCE_DIR     (root; exit 77 = skipped)
set -u
build=${1:?build dir}
src=${2:?source dir}
here=$(cd "$(dirname "$0")" && pwd)
. "$here/stage.sh"

if [ "$(id -u)" != 0 ]; then
  echo "SKIP: needs root (throwaway users and groups, uid changes); run ctest as root"
  exit 77
fi

tag=$(printf '%x%x' $$ $((RANDOM % 256)))
readers=d19r$tag admins=d19a$tag           # ds1928, ds1928-admin
svc=d19d$tag reader=d19u$tag admin=d19p$tag outsider=d19o$tag
run=/run/ds1928d-perm-$tag                  # RuntimeDirectory=
shm=/ds1928d-perm-$tag
pid=""
fail=0
cleanup() {
  if [ -n "$pid" ] && kill -0 "$pid" 2>/dev/null; then
    kill -TERM "$pid"
    timeout 20 tail --pid="$pid" -f /dev/null || kill -KILL "$pid"
  fi
  for u in $svc $reader $admin $outsider; do getent passwd "$u" >/dev/null && userdel "$u"; done
  for g in $readers $admins; do getent group "$g" >/dev/null && groupdel "$g"; done
  rm -rf "$run" "$run"-*
  rm -f /dev/shm/ds1928d-perm-"$tag"*
}
trap 'cleanup; unstage_programs' EXIT
stage_programs "$build/daemon/ds1928d" "$build/tools/ds1928ctl/ds1928ctl" ||
  { echo "FAIL: cannot stage the programs under /var/lib/ds1928d-test"; exit 1; }
daemon=${staged[ds1928d]} ctl=${staged[ds1928ctl]}
check() {  # check DESCRIPTION COMMAND...
  if "${@:2}"; then echo "ok:   $1"; else echo "FAIL: $1"; fail=1; fi
}
as() {  # as USER COMMAND...: with the user's uid, primary and supplementary groups
  local user=$1; shift
  setpriv --reuid="$user" --regid="$(id -g "$user")" --init-groups -- "$@"
}

groupadd --system "$readers" && groupadd --system "$admins" || exit 1
useradd --system --no-create-home --home-dir /nonexistent --shell /usr/sbin/nologin \
  --gid "$readers" "$svc" || exit 1
useradd --system --no-create-home --shell /usr/sbin/nologin --user-group \
  --groups "$readers" "$reader" || exit 1
useradd --system --no-create-home --shell /usr/sbin/nologin --user-group \
  --groups "$readers,$admins" "$admin" || exit 1
useradd --system --no-create-home --shell /usr/sbin/nologin --user-group "$outsider" || exit 1

# configure NAME SHM SOCKET: a configuration like the package's (groups set) in $run/NAME.yaml
configure() {
  sed -e "s|^\(  name:\) /ds1928d |\1 $2 |" \
      -e "s|^\(  path:\) /run/ds1928d/control.sock|\1 $3|" \
      -e "s|^\(  group:\) \"\"|\1 $readers|" \
      -e "s|^\(  privileged_group:\) ds1928-admin|\1 $admins|" \
      -e "s|^\(  hold_cpu_dma_latency:\) true|\1 false|" \
      "$src/config/simulated.yaml" > "$run/$1.yaml"
  chmod 0644 "$run/$1.yaml"
  [ "$(grep -c "$readers" "$run/$1.yaml")" = 2 ] && grep -q "privileged_group: $admins" "$run/$1.yaml" ||
    { echo "FAIL: could not derive the test configuration"; exit 1; }
}
# The daemon as the service user under the unit's settings.
service=("$here/as_service.sh" --user "$svc" --group "$readers" --rw "$run" -- "$daemon")

mkdir -m 0755 "$run"
chown "$svc:$readers" "$run"
configure main "$shm" "$run/control.sock"
pid=$(python3 "$here/notify_start.py" "$run" 60 "$run/daemon.log" -- "${service[@]}" \
        --config "$run/main.yaml")
[ -n "$pid" ] || { echo "FAIL: the daemon did not start as $svc"; exit 1; }
echo "ds1928d pid $pid as $svc (group $readers)"

echo "--- files"
sock_stat=$(stat -c '%A %U %G' "$run/control.sock")
shm_stat=$(stat -c '%A %U %G' "/dev/shm$shm")
wait_stat=$(stat -c '%A %U %G' "/dev/shm$shm.wait")
echo "  socket $sock_stat; shm $shm_stat; wait area $wait_stat"
check "socket srw-rw---- $svc $readers" test "$sock_stat" = "srw-rw---- $svc $readers"
check "shm -rw-r----- $svc $readers" test "$shm_stat" = "-rw-r----- $svc $readers"
check "wait area -rw-rw---- $svc $readers" test "$wait_stat" = "-rw-rw---- $svc $readers"

# ctl USER ARGS...: ds1928ctl as USER, JSON out; prints "<exit code> <output>"
ctl() {
  local user=$1; shift
  local out rc
  out=$(as "$user" "$ctl" --socket "$run/control.sock" --shm "$shm" --json --timeout 20000 "$@" 2>&1)
  rc=$?
  echo "$rc $out"
}
denied() { [[ "$1" == "1 "*'"permission_denied"'* ]]; }

echo "--- reader $reader (group $readers)"
r=$(ctl "$reader" status); echo "  status: ${r:0:120}"
check "reader gets status" grep -q '^0 .*"ok":true' <<<"$r"
r=$(ctl "$reader" position --axis 0); echo "  position: ${r:0:120}"
check "reader maps the shared memory" grep -q '^0 .*"cycle":' <<<"$r"
r=$(ctl "$reader" ack 0 1); echo "  ack: ${r:0:160}"
check "reader: ack-errors is permission_denied" denied "$r"
r=$(ctl "$reader" endat ack); echo "  endat ack: ${r:0:160}"
check "reader: endat-ack is permission_denied" denied "$r"
r=$(ctl "$reader" endat write-param 0xA9 3 0x1234); echo "  endat write-param: ${r:0:160}"
check "reader: endat-write-param is permission_denied" denied "$r"
r=$(ctl "$reader" endat reset); echo "  endat reset: ${r:0:160}"
check "reader: endat-reset is permission_denied" denied "$r"

echo "--- admin $admin (groups $readers, $admins)"
r=$(ctl "$admin" ack 0 1); echo "  ack: ${r:0:160}"
check "admin may acknowledge" grep -q '^0 .*"ok":true' <<<"$r"

echo "--- outsider $outsider"
r=$(ctl "$outsider" status); echo "  status: ${r:0:160}"
check "outsider cannot connect (exit 3, permission denied)" grep -qi '^3 .*permission denied' <<<"$r"
r=$(ctl "$outsider" position --axis 0); echo "  position: ${r:0:160}"
check "outsider cannot map the shared memory (exit 3, permission denied)" \
  grep -qi '^3 .*permission denied' <<<"$r"

kill -TERM "$pid"
timeout 20 tail --pid="$pid" -f /dev/null
pid=""

# refused NAME EXPECTED_MESSAGE SHM SOCKET: the daemon must fail to start, saying EXPECTED
refused() {
  configure "$1" "$3" "$4"
  local out rc
  out=$(timeout 60 "${service[@]}" --config "$run/$1.yaml" 2>&1)
  rc=$?
  echo "  $1: exit $rc: $(grep -E 'error' <<<"$out" | tail -1)"
  [ "$rc" != 0 ] && [ "$rc" != 124 ] && grep -q "$2" <<<"$out"
}
echo "--- planted files"
printf 'precious\n' > "$run/target"
chmod 0666 "$run/target"

ln -s "$run/target" "/dev/shm$shm-link"
chown -h "$outsider" "/dev/shm$shm-link"
check "shm: a planted symbolic link is refused" \
  refused shm-link "symbolic link" "$shm-link" "$run/shm-link.sock"
check "  ... and not followed" test "$(cat "$run/target")" = precious
check "  ... and not removed" test -L "/dev/shm$shm-link"

as "$outsider" sh -c "umask 022; printf x > /dev/shm$shm-foreign"
check "shm: another user's file is refused" \
  refused shm-foreign "another user" "$shm-foreign" "$run/shm-foreign.sock"
check "  ... and left as it was" test "$(stat -c '%U %s' "/dev/shm$shm-foreign")" = "$outsider 1"

ln -s "$run/target" "$run/link.sock"
chown -h "$outsider" "$run/link.sock"
check "socket: a planted symbolic link is refused" \
  refused sock-link "symbolic link" "$shm-s1" "$run/link.sock"
check "  ... and not followed or removed" test -L "$run/link.sock" -a "$(cat "$run/target")" = precious
check "  ... and the shm of the refused start is gone" test ! -e "/dev/shm$shm-s1"

python3 -c "import socket,sys; s=socket.socket(socket.AF_UNIX); s.bind(sys.argv[1])" "$run/foreign.sock"
chown "$outsider" "$run/foreign.sock"
check "socket: another user's socket is refused" \
  refused sock-foreign "socket of another user" "$shm-s2" "$run/foreign.sock"
check "  ... and not removed" test -S "$run/foreign.sock"

mkdir -m 0755 "$run-theirs"
chown "$outsider" "$run-theirs"
check "socket: a directory of another user is refused" \
  refused sock-dir "belongs to another user" "$shm-s3" "$run-theirs/control.sock"
check "  ... and nothing was created in it" test -z "$(ls -A "$run-theirs")"

mkdir -m 0755 "$run-real"
ln -s "$run-real" "$run-dirlink"
check "socket: a symlinked directory is refused" \
  refused sock-dirlink "directory is a symbolic link" "$shm-s4" "$run-dirlink/control.sock"
check "  ... and nothing was created behind it" test -z "$(ls -A "$run-real")"

[ "$fail" = 0 ] && echo "PASS: readers read, only admins change, outsiders and planted files are refused"
exit "$fail"
