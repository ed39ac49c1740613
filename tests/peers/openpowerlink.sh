#!/usr/bin/env bash
# Builds openPOWERLINK V2.7.2 (commit 048650a) — an independent POWERLINK stack used as a TEST PEER, not a
# dependency of the product — once into a cache outside the source tree, and prints where its demos are.
#
#   tests/peers/openpowerlink.sh            build when needed, then print the env file's lines
#   tests/peers/openpowerlink.sh --env-file build when needed, then print the path of the env file
#   tests/peers/openpowerlink.sh --locate   find (or fetch) the archive only, print its path; no build
#   tests/peers/openpowerlink.sh --fetch    fetch the pinned upstream commit now, print the archive's path
#   eval "$(tests/peers/openpowerlink.sh)"  -> OPL_DEMO_MN, OPL_DEMO_CN, OPL_MNOBD_CDC, OPL_PEER_DIR
#
# Archive openPOWERLINK_V2-048650a.tar.gz, looked for in this order:
#   1. $DS1928_PEERS_DIR/
#   2. ../shared/peers/ beside the checkout (where the project keeps its shared material)
#   3. the cache (below), where an earlier fetch left it
#   4. fetched: the pinned commit 048650a80db37fa372330c3a900d2c8edb327e47 (tag V2.7.2) from
#      $DS1928_PEER_UPSTREAM (default https://github.com/OpenAutomationTechnologies/openPOWERLINK_V2),
#      by its full hash (git checks every object against it, and the script checks the commit it got),
#      then `git archive` of the subset the tests use, the same subset ../shared/peers holds. At most
#      $DS1928_PEER_FETCH_TIMEOUT (120) seconds; DS1928_PEER_FETCH=0 never fetches.
# Exit 3 when the archive is nowhere and cannot be fetched: the message names every place looked at and the
# exact commands that get it. The tests (tests/lib/netns.sh use_openpowerlink) SKIP then (exit 77, counted by
# ctest) — except under CI (CI=true or DS1928_REQUIRE_PEERS=1), where they FAIL naming what is missing.
# Exit 2: Debian packages missing (not root); exit 1: the build failed.
#
# Cache: ${DS1928_PEER_CACHE:-/var/cache/ds1928-test}/openpowerlink-048650a, shared by every worktree and run.
# The build holds an flock on <cache>.lock, so two runs starting at once build it once; it is rebuilt when the
# archive's SHA-256 differs from the one recorded by the last complete build (the stamp is written last, so
# an interrupted build is redone). Build output goes to <cache>/build.log.
#
# Needs Debian's cmake, build-essential and libpcap-dev (installed with apt-get when missing and root). The
# flags are the ones measured on Debian 12 / gcc 12 (../shared/peers/README.md): -fcommon because the stack
# defines globals in headers, -Wno-error for gcc 12's new warnings; only the user-space pcap libraries.
set -euo pipefail

readonly ARCHIVE_NAME=openPOWERLINK_V2-048650a.tar.gz
readonly CACHE_NAME=openpowerlink-048650a
# DS1928_PEER_TEST_COMMIT replaces the pin in tests/peers/peer_locate_test.sh only (a local upstream).
readonly PINNED_COMMIT=${DS1928_PEER_TEST_COMMIT:-048650a80db37fa372330c3a900d2c8edb327e47}
readonly UPSTREAM=${DS1928_PEER_UPSTREAM:-https://github.com/OpenAutomationTechnologies/openPOWERLINK_V2}
# The subset of the upstream tree the tests build (the same as ../shared/peers/README.md lists).
readonly SUBSET=(apps/common apps/demo_cn_console apps/demo_mn_console cmake contrib license.md readme.md
  revision.md stack tools/linux)
readonly PEER_DEPS=(cmake build-essential libpcap-dev)

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source_root=$(cd "$here/../.." && pwd)

mode=print
case "${1:-}" in
  "") ;;
  --env-file) mode=env-file ;;
  --locate) mode=locate ;;
  --fetch) mode=fetch ;;
  -h | --help)
    sed -n '2,32p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 0
    ;;
  *)
    echo "openpowerlink.sh: unknown argument '$1' (use --env-file, --locate, --fetch or nothing)" >&2
    exit 64
    ;;
esac

log() { echo "openpowerlink.sh: $*" >&2; }

# --- the archive ------------------------------------------------------------------------------------------
cache_parent=${DS1928_PEER_CACHE:-/var/cache/ds1928-test}
fetched="$cache_parent/$ARCHIVE_NAME"

# The pinned commit from upstream, by its full hash, into $fetched. Returns non-zero (with the reason on
# stderr) when git is missing, the network does not answer, or what came is not the pinned commit.
fetch_archive() {
  local work got rc=0
  command -v git >/dev/null || { log "cannot fetch: git is not installed (apt-get install git)"; return 1; }
  mkdir -p "$cache_parent" || return 1
  work=$(mktemp -d "$cache_parent/fetch.XXXXXX") || return 1
  log "fetching openPOWERLINK $PINNED_COMMIT from $UPSTREAM"
  {
    git -C "$work" init -q &&
      GIT_TERMINAL_PROMPT=0 timeout "${DS1928_PEER_FETCH_TIMEOUT:-120}" \
        git -C "$work" fetch -q --depth 1 "$UPSTREAM" "$PINNED_COMMIT"
  } >&2 || rc=1
  if ((rc == 0)); then
    got=$(git -C "$work" rev-parse --verify -q 'FETCH_HEAD^{commit}' || true)
    if [[ "$got" != "$PINNED_COMMIT" ]]; then
      log "REFUSED: $UPSTREAM gave commit '${got:-none}', not the pinned $PINNED_COMMIT"
      rc=1
    fi
  fi
  if ((rc == 0)); then
    git -C "$work" archive --format=tar --prefix=openPOWERLINK_V2/ "$PINNED_COMMIT" "${SUBSET[@]}" |
      gzip -n >"$work/$ARCHIVE_NAME" && mv "$work/$ARCHIVE_NAME" "$fetched" || rc=1
  fi
  rm -rf "$work"
  ((rc == 0)) && log "fetched and checked: $fetched"
  return $rc
}

candidates=()
[[ -n "${DS1928_PEERS_DIR:-}" ]] && candidates+=("$DS1928_PEERS_DIR/$ARCHIVE_NAME")
candidates+=("$(dirname "$source_root")/shared/peers/$ARCHIVE_NAME" "$fetched")
archive=""
if [[ $mode != fetch ]]; then
  for c in "${candidates[@]}"; do
    if [[ -f "$c" ]]; then
      archive=$(readlink -f "$c")
      break
    fi
  done
fi
if [[ -z "$archive" && "${DS1928_PEER_FETCH:-1}" != 0 ]]; then
  # One fetch at a time: the tests that need the peer may start together.
  mkdir -p "$cache_parent"
  exec 8>"$fetched.lock"
  flock 8
  if [[ $mode != fetch && -f "$fetched" ]] || fetch_archive; then archive=$fetched; fi
  flock -u 8
fi
if [[ -z "$archive" ]]; then
  log "MISSING test peer archive $ARCHIVE_NAME (openPOWERLINK V2.7.2, commit $PINNED_COMMIT)."
  log "Looked for it at:"
  for c in "${candidates[@]}"; do log "  $c"; done
  [[ "${DS1928_PEER_FETCH:-1}" == 0 ]] && log "  (fetching from $UPSTREAM is off: DS1928_PEER_FETCH=0)"
  log "Get it with one of:"
  log "  DS1928_PEERS_DIR=/dir/holding/the/archive   (the archive from the project's shared/peers)"
  log "  $here/openpowerlink.sh --fetch   (needs access to ${UPSTREAM%/*}/)"
  log "  git clone $UPSTREAM opl && git -C opl archive --format=tar --prefix=openPOWERLINK_V2/ \\"
  log "      $PINNED_COMMIT ${SUBSET[*]} | gzip -n >DIR/$ARCHIVE_NAME"
  exit 3
fi
if [[ $mode == locate || $mode == fetch ]]; then
  echo "$archive"
  exit 0
fi

# --- Debian packages --------------------------------------------------------------------------------------
missing=()
for p in "${PEER_DEPS[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  if [[ $(id -u) == 0 ]]; then
    log "installing missing Debian packages: ${missing[*]}"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
      "${missing[@]}") >&2
  else
    log "MISSING Debian packages to build the test peer: ${missing[*]}. Run as root:"
    log "  apt-get update && apt-get install -y ${missing[*]}"
    exit 2
  fi
fi

# --- the cached build -------------------------------------------------------------------------------------
cache="$cache_parent/$CACHE_NAME"
mkdir -p "$cache_parent"
env_file="$cache/env.sh"
stamp="$cache/.archive-sha256"

# The recorded sum names the archive and the harness patch below: a change of either rebuilds.
sum="$(sha256sum "$archive" | cut -d' ' -f1)+edrv-send-locked-1"

built() {
  [[ -f "$stamp" && "$(cat "$stamp")" == "$sum" && -f "$env_file" ]] || return 1
  # shellcheck disable=SC1090
  (source "$env_file" && [[ -x "$OPL_DEMO_MN" && -x "$OPL_DEMO_CN" && -f "$OPL_MNOBD_CDC" ]])
}

# One harness fix to the peer, not to its protocol: its Linux pcap driver queues a transmit buffer
# under its mutex, releases the mutex, then sends; the buffer is freed when the capture handle sees
# the frame come back, matched against the head of the queue. Two threads send (the cycle timer's
# SoA, the MN's own ASnd from the SoA's transmit handler), so a thread preempted between its
# enqueue and its send puts frames on the wire in another order than the queue's: the head never
# matches again and the MN falls silent for good (seen in CI and under load, always right after
# the MN's own ASnd). Sending while the mutex is held keeps wire order and queue order one.
patch_edrv_send() {
  python3 - "$1" <<'PY'
import sys
path = sys.argv[1]
text = open(path).read()
old = """        pthread_mutex_unlock(&edrvInstance_l.mutex);

        pcapRet = pcap_sendpacket(edrvInstance_l.pPcap, pBuffer_p->pBuffer,
                                  (int)pBuffer_p->txFrameSize);
"""
new = """        pcapRet = pcap_sendpacket(edrvInstance_l.pPcap, pBuffer_p->pBuffer,
                                  (int)pBuffer_p->txFrameSize);
        pthread_mutex_unlock(&edrvInstance_l.mutex);
"""
if text.count(old) != 1:
    sys.exit("edrv-pcap_linux.c: the send path to patch was not found (openPOWERLINK changed?)")
open(path, "w").write(text.replace(old, new))
PY
}

build() {
  local src="$cache/src/openPOWERLINK_V2" jobs
  jobs=${DS1928_PEER_JOBS:-$(nproc)}
  rm -rf "$cache"
  mkdir -p "$cache/src"
  log "building openPOWERLINK from $archive into $cache (about 3 minutes on 2 cores; log: $cache/build.log)"
  {
    tar -C "$cache/src" -xzf "$archive"
    patch_edrv_send "$src/stack/src/kernel/edrv/edrv-pcap_linux.c" || return 1
    local flags="-fcommon -Wno-error"
    (cd "$src/stack/build/linux" &&
      cmake ../.. -DCMAKE_BUILD_TYPE=Release \
        -DCFG_COMPILE_LIB_MNAPP_KERNELINTF=OFF -DCFG_COMPILE_LIB_MNAPP_PCIEINTF=OFF \
        -DCFG_COMPILE_LIB_MNAPP_ZYNQINTF=OFF -DCFG_COMPILE_LIB_MN_SIM=OFF \
        -DCFG_COMPILE_LIB_CNAPP_KERNELINTF=OFF -DCFG_COMPILE_LIB_CNAPP_ZYNQINTF=OFF \
        -DCFG_COMPILE_LIB_CN_SIM=OFF -DCMAKE_C_FLAGS="$flags" &&
      make -j"$jobs" install)
    local demo
    for demo in demo_mn_console demo_cn_console; do
      (cd "$src/apps/$demo/build/linux" &&
        cmake ../.. -DCMAKE_BUILD_TYPE=Release -DCFG_BUILD_KERNEL_STACK="Link to Application" \
          -DCMAKE_C_FLAGS="$flags" &&
        make -j"$jobs" install)
    done
  } >"$cache/build.log.tmp" 2>&1 || {
    mv "$cache/build.log.tmp" "$cache/build.log" 2>/dev/null || true
    log "BUILD FAILED; last lines of $cache/build.log:"
    tail -n 30 "$cache/build.log" >&2 || true
    return 1
  }
  mv "$cache/build.log.tmp" "$cache/build.log"

  local bin="$src/bin/linux/$(uname -m)"
  local mn="$bin/demo_mn_console/demo_mn_console" cn="$bin/demo_cn_console/demo_cn_console"
  local cdc="$bin/demo_mn_console/mnobd.cdc"
  for f in "$mn" "$cn" "$cdc"; do
    [[ -f "$f" ]] || {
      log "BUILD INCOMPLETE: $f was not produced (see $cache/build.log)"
      return 1
    }
  done
  cat >"$env_file" <<EOF
# openPOWERLINK V2.7.2 (048650a) test peer, built from $archive (sha256 $sum)
OPL_PEER_DIR='$cache'
OPL_DEMO_MN='$mn'
OPL_DEMO_CN='$cn'
OPL_MNOBD_CDC='$cdc'
EOF
  # Last: only a complete build is reused.
  echo "$sum" >"$stamp"
  log "built: $cache"
}

exec 9>"$cache.lock"
flock 9
if ! built; then
  build || exit 1
fi
flock -u 9

if [[ $mode == env-file ]]; then
  echo "$env_file"
else
  grep -v '^#' "$env_file"
fi
