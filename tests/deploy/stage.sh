# Sourced by the deploy tests. stage_programs DIR PROGRAM...: copies the build tree's programs
# where the unit's sandbox and other users can reach them, and prints nothing.
#
# A checkout may lie anywhere: below /tmp or /var/tmp (which PrivateTmp= replaces), /home or
# /root (which ProtectHome= empties, and whose modes keep other users out anyway). The service
# user and the test users must still run the programs under test, so they run copies in a
# staging directory below /var/lib (visible, read-only under ProtectSystem=strict, never
# noexec the way /run and /dev/shm may be), removed by unstage_programs.
#
# After the call, staged[NAME] is the copy of each PROGRAM (NAME = its base name).
declare -A staged=()
stage_dir=""
stage_programs() {
  local parent=/var/lib/ds1928d-test p
  mkdir -p -m 0755 "$parent" || return 1
  stage_dir=$(mktemp -d "$parent/stage.XXXXXX") || return 1
  chmod 0755 "$stage_dir"
  for p in "$@"; do
    install -m 0755 "$p" "$stage_dir/" || return 1
    staged[$(basename "$p")]=$stage_dir/$(basename "$p")
  done
}
unstage_programs() {
  [ -n "$stage_dir" ] && rm -rf "$stage_dir"
  rmdir /var/lib/ds1928d-test 2>/dev/null || true
}
