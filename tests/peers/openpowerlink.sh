#!/usr/bin/env bash
# Builds openPOWERLINK V2.7.2 (commit 048650a) — an independent POWERLINK stack used as a TEST PEER, not a
# dependency of the product — once into a cache outside the source tree, and prints where its demos are.
#
#   tests/peers/openpowerlink.sh            build when needed, then print the env file's lines
#   tests/peers/openpowerlink.sh --env-file build when needed, then print the path of the env file
#   eval "$(tests/peers/openpowerlink.sh)"  -> OPL_DEMO_MN, OPL_DEMO_CN, OPL_MNOBD_CDC, OPL_PEER_DIR
#
# Archive: $DS1928_PEERS_DIR/openPOWERLINK_V2-048650a.tar.gz, else ../shared/peers/ relative to the source
# tree's parent (where the project keeps its shared material). A missing archive is an error (exit 2) that
# names what is missing and every place looked at: the tests that need the peer FAIL then, never skip.
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
readonly PEER_DEPS=(cmake build-essential libpcap-dev)

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
source_root=$(cd "$here/../.." && pwd)

mode=print
case "${1:-}" in
  "") ;;
  --env-file) mode=env-file ;;
  -h | --help)
    sed -n '2,19p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'
    exit 0
    ;;
  *)
    echo "openpowerlink.sh: unknown argument '$1' (use --env-file or nothing)" >&2
    exit 64
    ;;
esac

log() { echo "openpowerlink.sh: $*" >&2; }

# --- the archive ------------------------------------------------------------------------------------------
candidates=()
[[ -n "${DS1928_PEERS_DIR:-}" ]] && candidates+=("$DS1928_PEERS_DIR/$ARCHIVE_NAME")
candidates+=("$(dirname "$source_root")/shared/peers/$ARCHIVE_NAME")
archive=""
for c in "${candidates[@]}"; do
  if [[ -f "$c" ]]; then
    archive=$(readlink -f "$c")
    break
  fi
done
if [[ -z "$archive" ]]; then
  log "MISSING test peer archive $ARCHIVE_NAME (openPOWERLINK V2.7.2, commit 048650a)."
  log "Looked for it at:"
  for c in "${candidates[@]}"; do log "  $c"; done
  log "Put the archive there or set DS1928_PEERS_DIR to the directory that holds it."
  exit 2
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
cache_parent=${DS1928_PEER_CACHE:-/var/cache/ds1928-test}
cache="$cache_parent/$CACHE_NAME"
mkdir -p "$cache_parent"
env_file="$cache/env.sh"
stamp="$cache/.archive-sha256"

sum=$(sha256sum "$archive" | cut -d' ' -f1)

built() {
  [[ -f "$stamp" && "$(cat "$stamp")" == "$sum" && -f "$env_file" ]] || return 1
  # shellcheck disable=SC1090
  (source "$env_file" && [[ -x "$OPL_DEMO_MN" && -x "$OPL_DEMO_CN" && -f "$OPL_MNOBD_CDC" ]])
}

build() {
  local src="$cache/src/openPOWERLINK_V2" jobs
  jobs=${DS1928_PEER_JOBS:-$(nproc)}
  rm -rf "$cache"
  mkdir -p "$cache/src"
  log "building openPOWERLINK from $archive into $cache (about 3 minutes on 2 cores; log: $cache/build.log)"
  {
    tar -C "$cache/src" -xzf "$archive"
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
