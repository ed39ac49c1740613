#!/usr/bin/env python3
"""Prints why each skipped test did not run, after ctest's summary (which names them only).

Usage: skipped_reasons.py JUNIT_XML     (ctest --output-junit; prints nothing when none skipped)

A skipped test (exit 77) says why on a line starting with "SKIP:" (tests/CMakeLists.txt); ctest
hides the output of tests that did not fail, so `make test` prints these lines here. A test that
skipped because the openPOWERLINK peer archive is missing names the command that gets it.
"""
import sys
import xml.etree.ElementTree as ET


def reasons(junit_path):
    """[(test name, reason)] of the skipped tests, in the file's order."""
    out = []
    for case in ET.parse(junit_path).getroot().iter("testcase"):
        if case.get("status") != "notrun" and case.find("skipped") is None:
            continue
        text = case.findtext("system-out") or ""
        lines = [line.strip() for line in text.splitlines()]
        said = [line for line in lines if line.startswith("SKIP")]
        skipped = case.find("skipped")
        fallback = skipped.get("message", "") if skipped is not None else ""
        out.append((case.get("name", "?"), " / ".join(said) or
                    (f"no reason printed ({fallback})" if fallback else "no reason printed")))
    return out


def main():
    if len(sys.argv) != 2:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    try:
        found = reasons(sys.argv[1])
    except (OSError, ET.ParseError) as e:
        print(f"skipped_reasons: {sys.argv[1]}: {e}", file=sys.stderr)
        return 1
    if not found:
        return 0
    print(f"\nWhy {len(found)} test{'s' if len(found) != 1 else ''} did not run:")
    for name, why in found:
        print(f"  {name}: {why}")
    if any("openpowerlink.sh --fetch" in why for _, why in found):
        print("The openPOWERLINK peer tests run once the archive is there (the command above; "
              "it looks in ../shared/peers and $DS1928_PEERS_DIR).")
    return 0


if __name__ == "__main__":
    sys.exit(main())
