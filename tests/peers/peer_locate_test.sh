#!/usr/bin/env bash
# How a checkout finds the openPOWERLINK test peer (tests/peers/openpowerlink.sh) and what the tests
# that need it do without it (tests/lib/netns.sh use_openpowerlink), on a copy of the two scripts in
# a checkout below a fresh directory with no ../shared beside it (as a newcomer's clone):
#   1. nothing anywhere, fetching off     -> exit 3, every place looked at and the commands that get it;
#   2. an upstream that serves another commit than the pinned one -> REFUSED, exit 3, nothing cached;
#   3. an upstream that serves the commit asked for (the pin pointed at a local repository's commit,
#      DS1928_PEER_TEST_COMMIT) -> the archive in the cache holds exactly the subset, found again
#      afterwards without fetching;
#   4. DS1928_PEERS_DIR, then ../shared/peers beside the checkout, in that order;
#   5. use_openpowerlink without the archive: SKIP (77) naming the command; FAIL (1) under CI=true
#      and under DS1928_REQUIRE_PEERS=1, naming the archive.
# No root, no network (the upstreams are local repositories), no peer build (--locate / --fetch).
# Usage: peer_locate_test.sh BUILD_DIR SOURCE_DIR
set -u
src=${2:?source dir}
tmp=$(mktemp -d /tmp/peer_locate.XXXXXX)
trap 'rm -rf "$tmp"' EXIT
failed=0
fail() { echo "FAIL: $*"; failed=1; }
pass() { echo "ok: $*"; }
command -v git >/dev/null || { echo "SKIP: git not installed"; exit 77; }

clone=$tmp/work/clone
mkdir -p "$clone/tests/peers" "$clone/tests/lib"
cp "$src/tests/peers/openpowerlink.sh" "$clone/tests/peers/"
cp "$src/tests/lib/netns.sh" "$clone/tests/lib/"
archive_name=openPOWERLINK_V2-048650a.tar.gz
script=$clone/tests/peers/openpowerlink.sh
run() { env -u DS1928_PEERS_DIR -u CI -u DS1928_REQUIRE_PEERS DS1928_PEER_CACHE="$tmp/cache" "$@"; }

# 1. nowhere, no fetch
rc=0
out=$(run DS1928_PEER_FETCH=0 "$script" --locate 2>&1) || rc=$?
[[ $rc == 3 ]] || fail "1: exit $rc, expected 3: $out"
grep -q "$tmp/work/shared/peers/$archive_name" <<<"$out" || fail "1: ../shared/peers not named: $out"
grep -q "$tmp/cache/$archive_name" <<<"$out" || fail "1: the cache not named: $out"
grep -q -- "--fetch" <<<"$out" && grep -q "git clone https://github.com/OpenAutomationTechnologies" <<<"$out" ||
  fail "1: the commands that get the peer are not printed: $out"
((failed)) || pass "1: missing everywhere -> exit 3 naming the places and the commands"

# A local "upstream": a repository with the subset's layout plus a file outside the subset.
up=$tmp/upstream
mkdir -p "$up"/{stack/src,apps/common,apps/demo_cn_console,apps/demo_mn_console,apps/demo_other,cmake,contrib}
mkdir -p "$up"/tools/linux "$up"/tools/windows
for f in stack/src/a.c apps/common/b.c apps/demo_cn_console/c.c apps/demo_mn_console/d.c \
  apps/demo_other/e.c cmake/f.cmake contrib/g.h tools/linux/h.sh tools/windows/i.bat license.md \
  readme.md revision.md unrelated.txt; do echo "$f" >"$up/$f"; done
git -C "$up" init -q && git -C "$up" add -A &&
  git -C "$up" -c user.name=t -c user.email=t@t commit -q -m upstream || { echo "FAIL: git repo"; exit 1; }
local_commit=$(git -C "$up" rev-parse HEAD)

# 2. the upstream answers, but with a commit that is not the pinned one
rc=0
out=$(run DS1928_PEER_UPSTREAM="file://$up" "$script" --locate 2>&1) || rc=$?
if [[ $rc == 3 ]] && grep -q "REFUSED\|not our ref\|couldn't find remote ref\|upload-pack" <<<"$out" &&
  [[ ! -e "$tmp/cache/$archive_name" ]]; then
  pass "2: an upstream without the pinned commit -> refused, exit 3, nothing cached"
else
  fail "2: exit $rc (expected 3, refused, no archive): $out"
fi
# 3. fetch of the pinned commit (pointed at the local one for this test)
rc=0
out=$(run DS1928_PEER_UPSTREAM="file://$up" DS1928_PEER_TEST_COMMIT="$local_commit" "$script" --locate 2>&1) ||
  rc=$?
got=$(tail -n1 <<<"$out")
if [[ $rc == 0 && "$got" == "$tmp/cache/$archive_name" && -f "$got" ]]; then
  list=$(tar -tzf "$got" | grep -v '/$' | sort | tr '\n' ' ')
  want="openPOWERLINK_V2/apps/common/b.c openPOWERLINK_V2/apps/demo_cn_console/c.c openPOWERLINK_V2/apps/demo_mn_console/d.c openPOWERLINK_V2/cmake/f.cmake openPOWERLINK_V2/contrib/g.h openPOWERLINK_V2/license.md openPOWERLINK_V2/readme.md openPOWERLINK_V2/revision.md openPOWERLINK_V2/stack/src/a.c openPOWERLINK_V2/tools/linux/h.sh "
  [[ "$list" == "$want" ]] && pass "3: fetched by hash, the archive holds exactly the subset" ||
    fail "3: archive holds [$list], expected [$want]"
  # Found again from the cache, without an upstream.
  rc=0
  out=$(run DS1928_PEER_FETCH=0 "$script" --locate 2>&1) || rc=$?
  [[ $rc == 0 && "$(tail -n1 <<<"$out")" == "$tmp/cache/$archive_name" ]] &&
    pass "3: a fetched archive is found in the cache afterwards" || fail "3: not found in the cache: $out"
else
  fail "3: exit $rc, printed '$got': $out"
fi
rm -f "$tmp/cache/$archive_name"

# 4. DS1928_PEERS_DIR first, then beside the checkout
mkdir -p "$tmp/work/shared/peers" "$tmp/mine"
echo beside >"$tmp/work/shared/peers/$archive_name"
echo mine >"$tmp/mine/$archive_name"
out=$(run DS1928_PEER_FETCH=0 "$script" --locate 2>/dev/null)
[[ "$out" == "$tmp/work/shared/peers/$archive_name" ]] && pass "4: ../shared/peers beside the checkout" ||
  fail "4: beside the checkout: got '$out'"
out=$(run DS1928_PEER_FETCH=0 DS1928_PEERS_DIR="$tmp/mine" "$script" --locate 2>/dev/null)
[[ "$out" == "$tmp/mine/$archive_name" ]] && pass "4: DS1928_PEERS_DIR before ../shared/peers" ||
  fail "4: DS1928_PEERS_DIR: got '$out'"
rm -rf "$tmp/work/shared"

# 5. the tests' verdict without the archive
verdict() {
  run DS1928_PEER_FETCH=0 "$@" bash -c '. "$1/tests/lib/netns.sh"; src=$1; use_openpowerlink; echo UNREACHED' \
    _ "$clone" 2>&1
}
rc=0; out=$(verdict) || rc=$?
[[ $rc == 77 ]] && grep -q "^SKIP: .*openpowerlink.sh --fetch" <<<"$out" &&
  pass "5: no archive -> SKIP (77) with the command" || fail "5: exit $rc (expected 77 SKIP): $out"
rc=0; out=$(verdict CI=true) || rc=$?
[[ $rc == 1 ]] && grep -q "^FAIL: the openPOWERLINK test peer archive is missing" <<<"$out" &&
  grep -q "MISSING test peer archive $archive_name" <<<"$out" &&
  pass "5: CI=true -> FAIL naming the archive" || fail "5: CI=true: exit $rc: $out"
rc=0; out=$(verdict DS1928_REQUIRE_PEERS=1) || rc=$?
[[ $rc == 1 ]] && grep -q "^FAIL:" <<<"$out" && pass "5: DS1928_REQUIRE_PEERS=1 -> FAIL" ||
  fail "5: DS1928_REQUIRE_PEERS=1: exit $rc: $out"

((failed)) && exit 1
echo "PASS: peer_locate"
