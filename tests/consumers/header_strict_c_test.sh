#!/bin/bash
# include/ds1928/shm.h in strict ISO C: a consumer that includes it first compiles, links and runs
# with gcc and clang under -std=c99, -std=c11 and -std=c17 with -Wall -Wextra -pedantic -Werror and
# no feature-test macro of its own; and a consumer that breaks the one rule (a system header
# first, strict mode) is stopped by the header's own #error, which names the remedy.
#
# Usage: header_strict_c_test.sh BUILD_DIR SOURCE_DIR     (exit 77 = a compiler is missing)
set -u
src=${2:?source dir}
here=$(cd "$(dirname "$0")" && pwd)
for cc in gcc clang; do
  command -v "$cc" >/dev/null || { echo "SKIP: $cc missing (make deps-test installs it)"; exit 77; }
done
work=$(mktemp -d /tmp/ds1928-strict-c.XXXXXX)
trap 'rm -rf "$work"' EXIT
fail=0
name=/ds1928-strict-c-$$-$RANDOM   # never exists: the consumer must report ENOENT
for cc in gcc clang; do
  for std in c99 c11 c17; do
    exe=$work/consumer-$cc-$std
    if ! "$cc" -std=$std -Wall -Wextra -pedantic -Werror -I"$src/include" \
        "$here/strict_c_consumer.c" -o "$exe" 2>"$exe.log"; then
      echo "FAIL: $cc -std=$std:"; cat "$exe.log"; fail=1; continue
    fi
    out=$("$exe" "$name"); rc=$?
    if [ $rc = 0 ] && [ "$out" = "open $name: -$(python3 -c 'import errno; print(errno.ENOENT)')" ]; then
      echo "ok:   $cc -std=$std -Wall -Wextra -pedantic -Werror ($out)"
    else
      echo "FAIL: $cc -std=$std ran with exit $rc: $out"; fail=1
    fi
  done
done
# The rule's other side: <stdio.h> first in strict mode leaves clock_gettime() undeclared; the
# header must say so itself, not leave the user with an implicit-declaration error.
printf '#include <stdio.h>\n#include "ds1928/shm.h"\nint main(void) { return 0; }\n' >"$work/late.c"
if gcc -std=c11 -pedantic -I"$src/include" -c "$work/late.c" -o "$work/late.o" 2>"$work/late.log"; then
  echo "FAIL: strict C11 with <stdio.h> before the header compiled (clock_gettime undeclared?)"; fail=1
elif grep -q 'Include ds1928/shm.h first or define' "$work/late.log"; then
  echo "ok:   a system header first in strict mode stops at the header's #error"
else
  echo "FAIL: unexpected diagnostic:"; cat "$work/late.log"; fail=1
fi
exit $fail
