# Sourced by the shell tests that run programs in network namespaces joined by veth pairs (and by
# any shell test that wants the same verdicts and cleanup). One place for what every such test
# needs: the root check, a work directory, programs in the background, namespaces and veth pairs,
# cleanup on every exit, the verdict lines and polling for a log line.
#
#   require_root WHY                  exit 77 (ctest: skipped) unless root
#   require_programs FILE...          FAIL unless each is an executable file (built)
#   test_init NAME                    tag=$$, tmp=/tmp/NAME.XXXXXX, pids=(), failed=0, traps
#   on_cleanup 'COMMAND'              one more step for the cleanup (after the programs stopped)
#   track PID                         a background program to stop at cleanup
#   netns_add NS...                   network namespaces, deleted at cleanup
#   veth_pair NS_A IF_A NS_B IF_B     a veth pair between two namespaces, both ends up and with
#                                     carrier (a fresh veth has it only after the link watch ran)
#   fail MESSAGE / pass MESSAGE       verdict lines; fail prints the last FAIL_LOG_LINES (25)
#                                     lines of every $tmp/*.log and exits 1
#   wait_for FILE REGEX SECONDS       until a line of FILE matches (0) or the time is up (1)
#   field FILE NAME                   the last " NAME=value" number in FILE
# The work directory stays when the test failed or KEEP_TMP is set.

require_root() {
  [ "$(id -u)" = 0 ] && return 0
  echo "SKIP: needs root ($1); run ctest as root"
  exit 77
}

require_programs() {
  local p
  for p in "$@"; do [ -x "$p" ] || { echo "FAIL: $p not built"; exit 1; }; done
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
  local i
  for ((i = 0; i < $3 * 20; i++)); do
    grep -qE "$2" "$1" 2>/dev/null && return 0
    sleep 0.05
  done
  return 1
}

field() { sed -n "s/.*[ ]$2=\([-0-9.]*\).*/\1/p" "$1" | tail -n1; }
