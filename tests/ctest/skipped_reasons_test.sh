#!/bin/bash
# `make test`'s note on skipped tests (tests/ctest/skipped_reasons.py) on a real ctest run: a
# small project with a test that skips (77, "SKIP: ... --fetch"), one that passes and one that
# fails while printing a SKIP-like line. Only the skipped one is listed, with its reason and the
# peer hint; a run without skips prints nothing.
#
# Usage: skipped_reasons_test.sh BUILD_DIR SOURCE_DIR
set -u
src=${2:?source dir}
work=$(mktemp -d /tmp/ds1928-skipped-XXXXXX)
trap 'rm -rf "$work"' EXIT
fail() { echo "FAIL: $*"; exit 1; }
mkdir -p "$work/p"
cat >"$work/p/CMakeLists.txt" <<'CMAKE'
cmake_minimum_required(VERSION 3.16)
project(skips NONE)
enable_testing()
add_test(NAME needs_peer COMMAND sh -c "echo 'SKIP: the openPOWERLINK test peer archive is missing; get it with: tests/peers/openpowerlink.sh --fetch'; exit 77")
set_tests_properties(needs_peer PROPERTIES SKIP_RETURN_CODE 77)
add_test(NAME passes COMMAND sh -c "echo fine")
add_test(NAME fails COMMAND sh -c "echo 'SKIP: but exits 1'; exit 1")
set_tests_properties(needs_peer passes fails PROPERTIES LABELS some)
add_test(NAME other COMMAND sh -c "echo other")
CMAKE
cmake -S "$work/p" -B "$work/b" >/dev/null || fail "cmake"
(cd "$work/b" && ctest -j 2 --output-junit "$work/junit.xml" >/dev/null 2>&1)
out=$(python3 "$src/tests/ctest/skipped_reasons.py" "$work/junit.xml") || fail "exit $?: $out"
echo "$out"
grep -q "^Why 1 test did not run:" <<<"$out" || fail "no count line"
grep -q "^  needs_peer: SKIP: the openPOWERLINK .*openpowerlink.sh --fetch" <<<"$out" ||
  fail "the skipped test and its reason are not listed"
grep -q "fails\|passes" <<<"$out" && fail "a test that ran is listed"
grep -q "run once the archive is there" <<<"$out" || fail "no peer hint"
(cd "$work/b" && ctest -R other --output-junit "$work/none.xml" >/dev/null 2>&1)
out=$(python3 "$src/tests/ctest/skipped_reasons.py" "$work/none.xml") || fail "exit $? without skips"
[ -z "$out" ] || fail "output without skipped tests: $out"
echo "ok: skipped tests and their reasons listed, nothing when none skipped"
