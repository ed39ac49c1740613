#!/usr/bin/env bash
# Runs one openPOWERLINK console demo (or any program) inside network namespace NETNS with a private System V
# IPC namespace and its own tmpfs on /dev/shm: the demos use fixed names there, so an MN and a CN (or two
# test runs) on one machine would otherwise share — and corrupt — each other's queues.
#
#   tests/peers/opl_run.sh [--for SECONDS] NETNS -- PROGRAM [ARGS...]
#
# The demos poll the keyboard: stdin is a FIFO this script holds open for the whole run (EOF would read as a
# stream of key presses). The program is stopped with SIGTERM — the demos take it as "shut the stack down" —
# when this script gets SIGTERM/SIGINT or after --for SECONDS; if it has not exited 5 s later it is killed.
# Exit status: the program's (143 = it needed the SIGKILL or died of a signal).
set -euo pipefail

run_for=""
if [[ "${1:-}" == --for ]]; then
  run_for=$2
  shift 2
fi
if (($# < 3)) || [[ "$2" != -- ]]; then
  echo "usage: $0 [--for SECONDS] NETNS -- PROGRAM [ARGS...]" >&2
  exit 64
fi
netns=$1
shift 2

fifo_dir=$(mktemp -d /tmp/ds1928-opl-stdin.XXXXXX)
mkfifo "$fifo_dir/stdin"
# Read-write open: never blocks, and this script stays a writer, so the program never sees EOF.
exec 3<>"$fifo_dir/stdin"
rm -rf "$fifo_dir"

# ip netns exec, unshare (no --fork) and sh all exec: $! is the program itself.
ip netns exec "$netns" unshare --ipc --mount --propagation private -- \
  sh -c 'mount -t tmpfs -o size=64m,mode=1777 ds1928-opl-shm /dev/shm && exec "$@"' sh "$@" <&3 3>&- &
pid=$!

stop() {
  kill -TERM "$pid" 2>/dev/null || return 0
  local i
  for ((i = 0; i < 50; i++)); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.1
  done
  echo "opl_run.sh: $1 did not stop within 5 s of SIGTERM; killing it" >&2
  kill -KILL "$pid" 2>/dev/null || true
}

trap 'stop "$1"; wait "$pid"; exit $?' TERM INT

if [[ -n "$run_for" ]]; then
  # The timer is a child of this script; it is ended with the script.
  (sleep "$run_for" && kill -TERM $$) &
  timer=$!
  trap 'kill "$timer" 2>/dev/null || true' EXIT
fi

set +e
wait "$pid"
status=$?
exit "$status"
