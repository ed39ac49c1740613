#!/bin/bash
# Runs a test script over the Linux kernel's real CAN stack: boots Debian's own kernel in QEMU
# (TCG) with two emulated SJA1000 controllers (kvaser_pci) on one emulated CAN bus and a vcan,
# the host's root shared read-only over 9p and chrooted into, so the guest runs the build tree's
# binaries as they are. The kernel package (apt-get download), its modules and the initramfs are
# cached in the build tree and made once.
#
# Usage: run-guest.sh [--prepare-only] [--timeout SECONDS] [--host-check CMD] BUILD_DIR
#                     [GUEST_SCRIPT [ARGS...]]
#   GUEST_SCRIPT runs in the guest as root with can0, can1 (500 kbit/s, restart-ms 100) and vcan0 UP
#   (tests/canio/qemu/guest-main.sh). Its exit status is this script's: 0 pass, 1 fail, 77 skipped
#   (not root: only root may install the packages and share / with the guest as the files' owner).
#   --timeout: QEMU is killed after this many seconds (default 240; the guest's own budget is
#   2 minutes, a longer run is reported as a warning).
#   --host-check: once the guest script passed, `CMD WORK_DIR` runs on the host and its exit
#   status is this script's (0, 1, 77): it checks what the guest left in the run's work directory
#   ($CANIO_WORK in the guest) with the host's tools at native speed (e.g. tshark).
# Environment: CANIO_QEMU_CACHE (cache directory, default BUILD_DIR/canio-qemu),
#   CANIO_QEMU_KEEP=1 (keep the run's work directory even on success),
#   CANIO_QEMU_EXTRA / CANIO_QEMU_APPEND (more QEMU arguments / kernel command line).
set -u
here=$(cd "$(dirname "$0")" && pwd)
prepare_only=0
qemu_timeout=240
host_check=""
while [ $# -gt 0 ]; do
  case "$1" in
    --prepare-only) prepare_only=1; shift ;;
    --timeout) qemu_timeout=${2:?seconds}; shift 2 ;;
    --host-check) host_check=${2:?command}; shift 2 ;;
    *) break ;;
  esac
done
build=${1:?usage: run-guest.sh [--prepare-only] [--timeout S] [--host-check CMD] BUILD_DIR [GUEST_SCRIPT [ARGS...]]}
shift
build=$(cd "$build" && pwd) || exit 1
if [ $prepare_only = 0 ]; then
  script=${1:?guest script}
  shift
  script=$(cd "$(dirname "$script")" && pwd)/$(basename "$script")
  [ -x "$script" ] || { echo "FAIL: $script is not an executable file"; exit 1; }
fi

if [ "$(id -u)" != 0 ]; then
  echo "SKIP: the real-kernel CAN test needs root (Debian packages, QEMU's 9p share of /); run ctest as root"
  exit 77
fi

cache=${CANIO_QEMU_CACHE:-$build/canio-qemu}
mkdir -p "$cache" || exit 1
note() { echo "run-guest: $*"; }
fail() { echo "FAIL: $*"; exit 1; }

# --- packages (same list as the Makefile's TEST_DEPS) ------------------------------------------
packages="qemu-system-x86 busybox-static cpio kmod xz-utils can-utils iproute2"
ensure_packages() {
  local p missing="" installed
  installed=" $(dpkg-query -W -f='${db:Status-Abbrev}${Package} ' $packages 2>/dev/null) "
  for p in $packages; do
    [[ $installed == *" ii $p "* ]] || missing="$missing $p"
  done
  [ -z "$missing" ] && return 0
  note "installing Debian packages:$missing"
  (apt-get update -qq && DEBIAN_FRONTEND=noninteractive timeout 600 \
    apt-get install -y -qq --no-install-recommends $missing) || fail "cannot install$missing"
}

# --- kernel, modules, initramfs (cached; one preparer at a time) --------------------------------
# Modules the guest needs; their dependencies and load order come from modprobe --show-depends.
guest_modules="virtio_pci 9pnet_virtio 9p overlay can can_raw can_dev sja1000 kvaser_pci vcan"

kernel_package() {
  # linux-image-amd64 depends on the current linux-image-X.Y.Z-N-amd64. apt-cache parses every
  # package list (seconds): its answer is kept until the lists change (apt-get update).
  local stamp=$cache/kernel-package
  if [ -s "$stamp" ] && [ -z "$(find /var/lib/apt/lists -maxdepth 1 -newer "$stamp" -print -quit 2>/dev/null)" ]; then
    cat "$stamp"
    return
  fi
  apt-cache depends linux-image-amd64 2>/dev/null |
    sed -n 's/^ *Depends: \(linux-image-[0-9][^ ]*-amd64\)$/\1/p' | head -n1 | tee "$stamp"
}

prepare_kernel() {
  local pkg deb kver kdir tmpx m ko
  pkg=$(kernel_package)
  if [ -z "$pkg" ] && ! ls "$cache"/deb/linux-image-*_amd64.deb > /dev/null 2>&1; then
    note "apt-cache knows no linux-image-amd64: apt-get update"
    timeout 600 apt-get update -qq
    pkg=$(kernel_package)
  fi
  if [ -n "$pkg" ]; then
    deb=$(ls "$cache"/deb/"${pkg}"_*_amd64.deb 2>/dev/null | tail -n1)
    if [ -z "$deb" ]; then
      note "downloading $pkg (apt-get download, ~70 MB, once per build tree)"
      mkdir -p "$cache/deb.part" && rm -f "$cache"/deb.part/*
      (cd "$cache/deb.part" && timeout 600 apt-get download -q -o APT::Sandbox::User=root "$pkg") ||
        fail "apt-get download $pkg failed (run apt-get update?)"
      mkdir -p "$cache/deb" && mv "$cache"/deb.part/*.deb "$cache/deb/" || fail "no .deb downloaded"
      rmdir "$cache/deb.part"
      deb=$(ls "$cache"/deb/"${pkg}"_*_amd64.deb | tail -n1)
    fi
  else
    # No package lists (offline machine): a cached kernel package still does.
    deb=$(ls -t "$cache"/deb/linux-image-*_amd64.deb 2>/dev/null | head -n1)
    [ -n "$deb" ] || fail "apt-cache knows no linux-image-amd64 and none is cached: run apt-get update"
    note "apt-cache knows no linux-image-amd64; using cached $(basename "$deb")"
  fi
  pkg=$(dpkg-deb -f "$deb" Package)
  kver=${pkg#linux-image-}
  kdir=$cache/kernel-$kver
  if [ ! -f "$kdir/done" ]; then
    note "extracting $(basename "$deb"), depmod, collecting modules for $kver"
    rm -rf "$kdir" "$cache/extract"
    tmpx=$cache/extract
    mkdir -p "$tmpx" "$kdir/modules"
    dpkg-deb -x "$deb" "$tmpx" || fail "dpkg-deb -x $deb failed"
    depmod -b "$tmpx" "$kver" || fail "depmod -b failed"
    : > "$kdir/modules.load"
    for m in $guest_modules; do
      modprobe -d "$tmpx" -S "$kver" --show-depends "$m" > "$cache/deps" 2>&1 ||
        fail "modprobe --show-depends $m: $(cat "$cache/deps")"
      while read -r kind path _; do
        [ "$kind" = insmod ] || continue # "builtin X" needs nothing
        ko=$(basename "$path")
        grep -qx "$ko" "$kdir/modules.load" && continue
        cp "$path" "$kdir/modules/" || fail "cannot copy $path"
        echo "$ko" >> "$kdir/modules.load"
      done < "$cache/deps"
    done
    cp "$tmpx/boot/vmlinuz-$kver" "$kdir/vmlinuz" || fail "no vmlinuz-$kver in $deb"
    # An uncompressed vmlinux boots through its PVH entry point without the decompressor, which
    # under TCG halves the time to the first kernel message. Debian's kernel is XZ-compressed;
    # anything else (or no PVH) boots the bzImage.
    if grep -q '^CONFIG_PVH=y' "$tmpx/boot/config-$kver" && grep -q '^CONFIG_KERNEL_XZ=y' "$tmpx/boot/config-$kver"; then
      local off
      off=$(LC_ALL=C grep -abo $'\xfd''7zXZ' "$kdir/vmlinuz" | head -n1 | cut -d: -f1)
      # xz complains about the bytes after the stream: the ELF magic is the verdict.
      [ -n "$off" ] && tail -c +$((off + 1)) "$kdir/vmlinuz" | xz -dcq > "$kdir/vmlinux" 2> /dev/null
      if [ "$(head -c4 "$kdir/vmlinux" | od -An -tx1 | tr -d ' ')" = 7f454c46 ]; then
        note "vmlinux (PVH entry) unpacked from vmlinuz"
      else
        rm -f "$kdir/vmlinux"
      fi
    fi
    rm -rf "$tmpx" "$cache/deps"
    touch "$kdir/done"
  fi
  kernel=$kdir/vmlinuz
  [ -f "$kdir/vmlinux" ] && kernel=$kdir/vmlinux

  # The initramfs: rebuilt when /init, busybox or the module list change.
  local busybox=/bin/busybox key root
  [ -x $busybox ] || fail "$busybox missing (busybox-static)"
  key=$(cat "$here/init" "$busybox" "$kdir/modules.load" | sha256sum | cut -c1-16)
  initrd=$cache/initrd-$kver-$key.gz
  if [ ! -f "$initrd" ]; then
    note "building $(basename "$initrd")"
    root=$cache/initrd.root
    rm -rf "$root" && mkdir -p "$root/bin" "$root/modules"
    cp $busybox "$root/bin/busybox" && cp "$here/init" "$root/init" && chmod 755 "$root/init" &&
      cp "$kdir"/modules/*.ko "$root/modules/" && cp "$kdir/modules.load" "$root/modules.load" ||
      fail "cannot assemble the initramfs"
    (cd "$root" && find . | cpio -o -H newc --quiet | gzip -1) > "$initrd.part" || fail "cpio failed"
    mv "$initrd.part" "$initrd"
    rm -rf "$root"
    ls "$cache"/initrd-*.gz | grep -vxF "$initrd" | xargs -r rm -f # older keys
  fi
}

prep_start=$EPOCHREALTIME
exec 9> "$cache/.lock"
timeout 900 flock 9 || fail "cache $cache stays locked by another run"
ensure_packages
prepare_kernel
flock -u 9
exec 9>&-
note "kernel $(basename "$(dirname "$kernel")"), initramfs $(basename "$initrd") (ready in $(awk -v a="$prep_start" -v b="$EPOCHREALTIME" 'BEGIN{printf "%.1f", b-a}') s)"
[ $prepare_only = 1 ] && exit 0

# --- one guest run ------------------------------------------------------------------------------
# The work directory lives in the build tree (the guest sees the host's whole root, /tmp included:
# init lays a writable overlay over it before it mounts the work directory).
work=$(mktemp -d "$cache/run.XXXXXX") || fail "cannot create a work directory"
case "$work" in *[[:space:]]*) fail "the build directory path contains white space: $work" ;; esac
cleanup() {
  if [ "${rc:-1}" = 0 ] && [ -z "${CANIO_QEMU_KEEP:-}" ]; then rm -rf "$work"; else echo "run-guest: logs kept in $work"; fi
}
trap cleanup EXIT
trap 'exit 1' INT TERM

{
  echo '#!/bin/bash'
  printf 'export CANIO_WORK=%q CANIO_BUILD=%q CANIO_SOURCE=%q\n' "$work" "$build" "$(cd "$here/../../.." && pwd)"
  printf 'cd %q && ' "$PWD"
  printf 'exec %q' "$here/guest-main.sh"
  printf ' %q' "$script" "$@"
  echo
} > "$work/run.sh"
chmod +x "$work/run.sh"

# Boot speed under TCG: qboot (when Debian's qemu ships it) starts the kernel sooner than SeaBIOS,
# and mitigations=off spares the page-table switch on every syscall (a throwaway test guest).
bios=()
[ -f /usr/share/qemu/qboot.rom ] && bios=(-bios /usr/share/qemu/qboot.rom)
# Guest budget: the command gets what is left of the QEMU timeout after a generous boot allowance.
cmd_timeout=$((qemu_timeout - 25))
stamp() {
  local line
  while IFS= read -r line; do printf '%s %s\n' "$EPOCHREALTIME" "${line%$'\r'}"; done
}
# no_timer_check: on a busy host the emulated CPU can be too slow for the kernel's IO-APIC timer
# check, which then panics ("IO-APIC + timer doesn't work!").
boot_guest() {
  t0=$EPOCHREALTIME
  timeout -k 5 "$qemu_timeout" qemu-system-x86_64 \
    -nodefaults -no-user-config -display none -serial stdio -no-reboot \
    "${bios[@]}" ${CANIO_QEMU_EXTRA:-} -machine pc -cpu max -m 768 -smp "${CANIO_QEMU_SMP:-1}" \
    -kernel "$kernel" -initrd "$initrd" \
    -append "console=ttyS0 quiet panic=-1 mitigations=off no_timer_check ${CANIO_QEMU_APPEND:-} ds1928.work=$work ds1928.timeout=$cmd_timeout" \
    -virtfs local,path=/,mount_tag=host,security_model=none,readonly=on,multidevs=remap \
    -virtfs local,path="$work",mount_tag=work,security_model=none \
    -object can-bus,id=canbus0 \
    -device kvaser_pci,canbus=canbus0 \
    -device kvaser_pci,canbus=canbus0 \
    < /dev/null 2>&1 | stamp > "$work/console.log"
  qemu_rc=${PIPESTATUS[0]}
  t_end=$EPOCHREALTIME
}
boot_guest
# A guest that never reached its command did not run the test: boot once more (an emulated boot
# on an overloaded host is the only thing this retries; the test's own failures are final).
if ! grep -q "ds1928-guest: command start" "$work/console.log" && [ "$qemu_rc" != 124 ] && [ "$qemu_rc" != 137 ]; then
  note "the guest did not reach its command (QEMU exit $qemu_rc); console tail:"
  tail -n 5 "$work/console.log"
  note "booting once more"
  mv "$work/console.log" "$work/console.1.log"
  boot_guest
fi

secs() { awk -v a="$1" -v b="$2" 'BEGIN{printf "%.1f", b-a}'; }
t_cmd=$(sed -n 's/^\([0-9.]*\) ds1928-guest: command start.*/\1/p' "$work/console.log" | head -n1)
t_exit=$(sed -n 's/^\([0-9.]*\) ds1928-guest: command exit.*/\1/p' "$work/console.log" | head -n1)
show_logs() {
  echo "---- guest console (tail) $work/console.log"
  tail -n 30 "$work/console.log"
  [ -f "$work/init.log" ] && { echo "---- $work/init.log"; cat "$work/init.log"; }
  [ -f "$work/guest.log" ] && { echo "---- guest log (tail) $work/guest.log"; tail -n 60 "$work/guest.log"; }
}
if [ -n "$t_cmd" ]; then
  note "boot-to-command $(secs "$t0" "$t_cmd") s, command $([ -n "$t_exit" ] && echo "$(secs "$t_cmd" "$t_exit") s" || echo "did not finish"), whole guest run $(secs "$t0" "$t_end") s (host wall clock)"
else
  note "guest never reached its command (whole run $(secs "$t0" "$t_end") s)"
fi
whole=$(secs "$t0" "$t_end")
if awk -v w="$whole" 'BEGIN{exit !(w > 120)}'; then
  note "WARNING: the guest run took ${whole} s, more than its 2-minute budget (host load $(cut -d' ' -f1-3 /proc/loadavg))"
fi
if [ "$qemu_rc" = 124 ] || [ "$qemu_rc" = 137 ]; then
  show_logs
  fail "QEMU killed after ${qemu_timeout}s"
fi
if [ ! -f "$work/rc" ]; then
  show_logs
  fail "the guest wrote no exit status (QEMU exit $qemu_rc)"
fi
rc=$(cat "$work/rc")
if [ "$rc" != 0 ]; then
  show_logs
  fail "guest script $(basename "$script") exited $rc"
fi
cat "$work/guest.log"
if [ -n "$host_check" ]; then
  note "host check: $host_check"
  "$host_check" "$work"
  rc=$?
  case $rc in
    0) ;;
    77) note "SKIP: the host check $(basename "$host_check") was skipped"; exit 77 ;;
    *) fail "host check $(basename "$host_check") exited $rc" ;;
  esac
fi
note "PASS $(basename "$script")"
exit 0
