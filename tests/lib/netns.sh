# Sourced by the shell tests that run programs in network namespaces joined by veth pairs (and by
# any shell test that wants the same verdicts and cleanup). One place for what every such test
# needs: the root check, a work directory, programs in the background, namespaces and veth pairs,
# cleanup on every exit, the verdict lines and polling for a log line.
#
#   use_trees BUILD_DIR SOURCE_DIR    build=, src= and the programs of the build tree: sim
#                                     (ds1928-sim), daemon (ds1928d), ctl (ds1928ctl), mn
#                                     (bench's pl_mn_runner)
#   use_openpowerlink                 the openPOWERLINK peer's variables (OPL_*), built once into
#                                     its cache by tests/peers/openpowerlink.sh; without its archive
#                                     SKIP (77) with the command that gets it, but FAIL under CI=true
#                                     or DS1928_REQUIRE_PEERS=1; FAIL when the build fails
#   require_root WHY                  exit 77 (ctest: skipped) unless root
#   require_programs FILE...          FAIL unless each is an executable file (built)
#   require_tools COMMAND...          FAIL unless each is installed (jq, tshark: make deps-test)
#   skip_unless_tools COMMAND...      exit 77 (skipped) unless each is installed
#   test_init NAME                    tag=$$, tmp=/tmp/NAME.XXXXXX, pids=(), failed=0, traps
#   on_cleanup 'COMMAND'              one more step for the cleanup (after the programs stopped)
#   track PID                         a background program to stop at cleanup
#   netns_add NS...                   network namespaces, deleted at cleanup
#   veth_pair NS_A IF_A NS_B IF_B     a veth pair between two namespaces, both ends up and with
#                                     carrier (a fresh veth has it only after the link watch ran)
#   fail MESSAGE / pass MESSAGE       verdict lines; fail prints the last FAIL_LOG_LINES (25)
#                                     lines of every $tmp/*.log and exits 1
#   wait_for FILE REGEX SECONDS [COUNT]
#                                     until COUNT (1) lines of FILE match (0) or the time is up
#                                     (1); the bound counts polls of 50 ms, SECONDS × 20 ×
#                                     $wait_scale (1): a loaded machine stretches it
#   until_true SECONDS COMMAND...     until COMMAND succeeds (0), polled every 100 ms; the bound
#                                     is wall-clock time (for a limit the test measures), and
#                                     COMMAND's last try after it decides
#   field FILE NAME                   the last " NAME=value" number in FILE
# The work directory stays when the test failed or KEEP_TMP is set. A test starts with
#   set -u
#   . "${2:?source dir}/tests/lib/netns.sh"
#   use_trees "$1" "$2"

use_trees() {
  build=${1:?build dir}
  src=${2:?source dir}
  sim=$build/tools/ds1928-sim/ds1928-sim
  daemon=$build/daemon/ds1928d
  ctl=$build/tools/ds1928ctl/ds1928ctl
  mn=$build/bench/powerlink/pl_mn_runner
}

use_openpowerlink() {
  local env rc=0
  # Minutes the first time (the build), then read from the cache.
  env=$("$src/tests/peers/openpowerlink.sh") || rc=$?
  if ((rc == 3)); then
    # The archive is nowhere (the message above says where it looked and how to get it).
    if [ "${CI:-}" = true ] || [ "${DS1928_REQUIRE_PEERS:-0}" = 1 ]; then
      echo "FAIL: the openPOWERLINK test peer archive is missing (required: CI=${CI:-} DS1928_REQUIRE_PEERS=${DS1928_REQUIRE_PEERS:-0})"
      exit 1
    fi
    echo "SKIP: the openPOWERLINK test peer archive is missing; get it with:" \
      "$src/tests/peers/openpowerlink.sh --fetch  (or set DS1928_PEERS_DIR, see the message above)"
    exit 77
  fi
  ((rc == 0)) || {
    echo "FAIL: the openPOWERLINK test peer is not available (see the message above)"
    exit 1
  }
  eval "$env"
}

require_root() {
  [ "$(id -u)" = 0 ] && return 0
  echo "SKIP: needs root ($1); run ctest as root"
  exit 77
}

require_programs() {
  local p
  for p in "$@"; do [ -x "$p" ] || { echo "FAIL: $p not built"; exit 1; }; done
}

require_tools() {
  local t
  for t in "$@"; do command -v "$t" >/dev/null || { echo "FAIL: $t not installed"; exit 1; }; done
}

skip_unless_tools() {
  local t
  for t in "$@"; do command -v "$t" >/dev/null || { echo "SKIP: $t not installed"; exit 77; }; done
}

test_init() {
  tag=$$
  tmp=$(mktemp -d "/tmp/$1.XXXXXX") || { echo "FAIL: cannot create a work directory"; exit 1; }
  pids=()
  failed=0
  _cleanup_steps=()
  _namespaces=()
  trap _test_cleanup EXIT
  trap 'exit 1' INT TERM
}

on_cleanup() { _cleanup_steps+=("$1"); }
track() { pids+=("$1"); }

_test_cleanup() {
  local step p ns
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null; done
  for p in "${pids[@]}"; do wait "$p" 2>/dev/null; done
  for step in "${_cleanup_steps[@]}"; do eval "$step"; done
  for ns in "${_namespaces[@]}"; do ip netns del "$ns" 2>/dev/null; done
  if [ "${failed:-0}" = 0 ] && [ -z "${KEEP_TMP:-}" ]; then rm -rf "$tmp"; else echo "logs kept in $tmp"; fi
}

netns_add() {
  local ns
  for ns in "$@"; do
    ip netns add "$ns" || fail "cannot create network namespace $ns"
    _namespaces+=("$ns")
  done
}

veth_pair() {
  local i
  ip link add "$2" netns "$1" type veth peer name "$4" netns "$3" || fail "veth $2/$4"
  ip -n "$1" link set "$2" up && ip -n "$3" link set "$4" up || fail "veth $2/$4 up"
  for ((i = 0; i < 200; i++)); do
    ip -n "$1" link show "$2" | grep -q LOWER_UP && ip -n "$3" link show "$4" | grep -q LOWER_UP &&
      return 0
    sleep 0.05
  done
  fail "veth $2/$4 has no carrier after 10 s"
}

fail() {
  local f
  echo "FAIL: $*"
  failed=1
  for f in "$tmp"/*.log; do
    [ -e "$f" ] || continue
    echo "---- $f"
    tail -n "${FAIL_LOG_LINES:-25}" "$f"
  done
  exit 1
}

pass() { echo "ok: $*"; }

wait_for() {
  local file=$1 regex=$2 count=${4:-1} i
  for ((i = 0; i < $3 * 20 * ${wait_scale:-1}; i++)); do
    if [ "$count" = 1 ]; then
      grep -qE "$regex" "$file" 2>/dev/null && return 0
    else
      [ "$(grep -cE "$regex" "$file" 2>/dev/null)" -ge "$count" ] 2>/dev/null && return 0
    fi
    sleep 0.05
  done
  return 1
}

until_true() {
  local end=$((SECONDS + $1))
  shift
  while ((SECONDS < end)); do "$@" && return 0; sleep 0.1; done
  "$@"
}

field() { sed -n "s/.*[ ]$2=\([-0-9.]*\).*/\1/p" "$1" | tail -n1; }
