#!/bin/bash
# Runs a command the way systemd runs ds1928d.service, for hosts where systemd is not PID 1 (CI
# containers, VMs booted by another init): the settings of systemd/ds1928d.service applied by
# hand with util-linux tools.
#
#   User=/Group=                          setpriv --reuid/--regid, supplementary groups of the user
#   AmbientCapabilities=/CapabilityBoundingSet=  setpriv --inh-caps/--ambient-caps/--bounding-set
#   NoNewPrivileges=yes                   setpriv --no-new-privs
#   LimitRTPRIO=99 / LimitMEMLOCK=infinity  prlimit (needs CAP_SYS_RESOURCE; where the host lacks
#                                         it the hard limits stay, and SCHED_FIFO/mlockall rest on
#                                         CAP_SYS_NICE/CAP_IPC_LOCK alone — said on stderr)
#   ProtectSystem=strict                  every mount read-only except /dev, /proc, /sys and the
#                                         --rw directories (RuntimeDirectory=)
#   ProtectHome=yes / PrivateTmp=yes      empty read-only /home, /root; fresh /tmp, /var/tmp
#   UMask=0077                            umask
# Not applied (they need systemd as PID 1 or a seccomp loader): SystemCallFilter=,
# RestrictAddressFamilies=, DevicePolicy=, IPAddressDeny=, the Protect{Kernel*,Clock,...}= and
# MemoryDenyWriteExecute= settings.
#
# Usage: as_service.sh --user USER|UID --group GROUP|GID [--rw DIR]... -- COMMAND [ARG]...
# Runs as root; execs COMMAND (same PID), so a caller may wait for it or signal it.
set -eu
caps=+net_raw,+sys_nice,+ipc_lock  # AmbientCapabilities= of the unit
user="" group="" rw=()
while [ $# -gt 0 ]; do
  case "$1" in
    --user) user=$2; shift 2 ;;
    --group) group=$2; shift 2 ;;
    --rw) rw+=("$2"); shift 2 ;;
    --inside) inside=1; shift ;;
    --) shift; break ;;
    *) echo "as_service.sh: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -n "$user" ] && [ -n "$group" ] && [ $# -gt 0 ] || { echo "usage: $0 --user U --group G [--rw DIR]... -- CMD" >&2; exit 2; }

if [ -z "${inside:-}" ]; then
  # The unit's PrivateTmp and ProtectHome hide these trees: a command inside would not exist.
  case "$(readlink -f "$(command -v "$1" || echo "$1")")" in
    /tmp/* | /var/tmp/* | /home/* | /root/*)
      echo "as_service.sh: $1 lies where the unit's PrivateTmp/ProtectHome hide it; build outside /tmp, /var/tmp, /home and /root" >&2
      exit 2 ;;
  esac
  args=(--user "$user" --group "$group")
  for d in "${rw[@]}"; do args+=(--rw "$d"); done
  # A private mount namespace: the mounts below vanish with the process. No --fork: the command
  # keeps this PID.
  exec unshare --mount --propagation private -- "$0" --inside "${args[@]}" -- "$@"
fi

# --- inside the new mount namespace, still root ---
for d in "${rw[@]}"; do mount --bind "$d" "$d"; done
mount -t tmpfs -o mode=1777,nosuid,nodev tmpfs /tmp
[ -d /var/tmp ] && mount -t tmpfs -o mode=1777,nosuid,nodev tmpfs /var/tmp
for d in /home /root; do [ -d "$d" ] && mount -t tmpfs -o ro,mode=0755 tmpfs "$d"; done
# ProtectSystem=strict: read-only bind remount of every mount point but the API file systems,
# the private /tmp and the writable directories. Deepest first is not needed: each remount
# changes one mount only.
keep="^(/dev|/proc|/sys|/tmp|/var/tmp|/home|/root)(/|$)"
while read -r mp; do
  mp=$(printf '%b' "$mp")  # mountinfo escapes blanks as \040
  [[ "$mp" =~ $keep ]] && continue
  skip=""
  for d in "${rw[@]}"; do [ "$mp" = "$d" ] && skip=1; done
  [ -n "$skip" ] && continue
  mount -o remount,bind,ro "$mp" 2>/dev/null || true
done < <(awk '{print $5}' /proc/self/mountinfo)
if touch /usr/.as_service_probe 2>/dev/null || touch /etc/.as_service_probe 2>/dev/null; then
  rm -f /usr/.as_service_probe /etc/.as_service_probe
  echo "as_service.sh: could not make /usr and /etc read-only" >&2
  exit 1
fi

if ! prlimit --pid $$ --rtprio=99:99 --memlock=unlimited:unlimited 2>/dev/null; then
  echo "as_service.sh: LimitRTPRIO/LimitMEMLOCK not applicable here (no CAP_SYS_RESOURCE:" \
       "hard limits rtprio $(ulimit -Hr), memlock $(ulimit -Hl) KiB stay);" \
       "SCHED_FIFO and mlockall rest on CAP_SYS_NICE and CAP_IPC_LOCK" >&2
fi
umask 0077
if [[ "$user" =~ ^[0-9]+$ ]]; then groups_opt=--clear-groups; else groups_opt=--init-groups; fi
exec setpriv --reuid="$user" --regid="$group" $groups_opt \
  --inh-caps=-all,$caps --ambient-caps=-all,$caps --bounding-set=-all,$caps \
  --no-new-privs -- "$@"
