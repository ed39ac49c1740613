#!/usr/bin/env python3
"""The suite's own registration: every test's ctest properties are what CMake was told.

Catch's discovery once flattened a test's properties into one list, so a second label became a
property of its own ("rt" = "TIMEOUT"), a test without labels got the label "TIMEOUT", and neither
kept its timeout; `ctest -L rt` then missed tests. This reads `ctest --show-only=json-v1` and fails
on any of that, and on a POWERLINK test that `-L powerlink` (make stress) would not select.

  ctest_properties_test.py BUILD_DIR [--json FILE]   (FILE: a saved dump, to see the check fail)
"""
import json
import re
import subprocess
import sys


def main() -> int:
    build = sys.argv[1]
    if len(sys.argv) == 4 and sys.argv[2] == "--json":
        with open(sys.argv[3]) as f:
            dump = json.load(f)
    else:
        out = subprocess.run(["ctest", "--show-only=json-v1"], cwd=build, check=True,
                             capture_output=True, text=True).stdout
        dump = json.loads(out)
    errors = []
    for test in dump["tests"]:
        name = test["name"]
        props = {p["name"]: p["value"] for p in test.get("properties", [])}
        for key in props:
            if not re.fullmatch(r"[A-Z][A-Z_]*", key):
                errors.append(f"{name}: property '{key}' is not a ctest property (a split list?)")
        labels = props.get("LABELS", [])
        for label in labels:
            if not re.fullmatch(r"[a-z][a-z0-9_]*", label):
                errors.append(f"{name}: label '{label}' is not one of ours (a property name?)")
        if "TIMEOUT" not in props:
            errors.append(f"{name}: no TIMEOUT of its own")
        program = test.get("command", [""])[0]
        powerlink = ("/tests/powerlink/" in program or name.startswith("integration_powerlink_")
                     or name == "capture_powerlink")
        if powerlink and "powerlink" not in labels:
            errors.append(f"{name}: a POWERLINK test without the label 'powerlink'")
    for e in errors:
        print("FAIL:", e)
    if errors:
        return 1
    print(f"ok: {len(dump['tests'])} tests, every property and label as registered")
    return 0


if __name__ == "__main__":
    sys.exit(main())
