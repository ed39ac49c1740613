# Shell helpers for the guest scripts (sourced). Every process start is expensive in a TCG guest,
# so the waits read files with bash builtins and bound themselves by the clock, not by a count.

# until_true SECONDS CMD...: run CMD until it succeeds; false once SECONDS have passed.
until_true() {
  local secs=$1 deadline now
  shift
  deadline=$((${EPOCHREALTIME/./} + secs * 1000000))
  while :; do
    "$@" && return 0
    now=${EPOCHREALTIME/./}
    ((now < deadline)) || return 1
    sleep 0.05
  done
}

# file_has FILE REGEX: some line of FILE matches the extended REGEX (no grep process).
file_has() {
  local line lines
  mapfile -t lines < "$1" 2> /dev/null || return 1
  for line in "${lines[@]}"; do
    [[ $line =~ $2 ]] && return 0
  done
  return 1
}

# file_count FILE REGEX: prints how many lines of FILE match REGEX.
file_count() {
  local line lines n=0
  mapfile -t lines < "$1" 2> /dev/null
  for line in "${lines[@]}"; do
    [[ $line =~ $2 ]] && n=$((n + 1))
  done
  echo $n
}
