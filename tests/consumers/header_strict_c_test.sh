#!/bin/bash
# include/ds1928/shm.h in strict ISO C: a consumer compiles, links and runs with gcc and clang
# under -std=c99, -std=c11 and -std=c17 with -Wall -Wextra -pedantic -Werror and no feature-test
# macro of its own, whether the header comes first or after a system header (then glibc has
# already settled on ISO C only and the header must declare what it needs itself); and, as a
# user may choose a narrower one, with -D_POSIX_C_SOURCE=200809L (no syscall() there).
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
enoent=$(python3 -c 'import errno; print(errno.ENOENT)')
for cc in gcc clang; do
  for std in c99 c11 c17; do
    for variant in header-first system-header-first posix-2008; do
      case $variant in
        header-first) flags=() ;;
        system-header-first) flags=(-DSYSTEM_HEADER_FIRST) ;;
        posix-2008) flags=(-D_POSIX_C_SOURCE=200809L) ;;
      esac
      exe=$work/consumer-$cc-$std-$variant
      if ! "$cc" -std=$std -Wall -Wextra -pedantic -Werror "${flags[@]}" -I"$src/include" \
          "$here/strict_c_consumer.c" -o "$exe" 2>"$exe.log"; then
        echo "FAIL: $cc -std=$std ($variant):"; cat "$exe.log"; fail=1; continue
      fi
      out=$("$exe" "$name"); rc=$?
      if [ $rc = 0 ] && [ "$out" = "open $name: -$enoent, clock ok, timebase ok" ]; then
        echo "ok:   $cc -std=$std -Wall -Wextra -pedantic -Werror, $variant ($out)"
      else
        echo "FAIL: $cc -std=$std ($variant) ran with exit $rc: $out"; fail=1
      fi
    done
  done
done
exit $fail
