#!/usr/bin/env python3
"""hal_compare.py's checks on made-up recordings: each passes a consistent one and fails one with
exactly one fault of the kind it exists to catch (a torn pair, a value that differs from
ds1928ctl's, a read given up that still claims valid, a system call of the realtime function)."""
import json
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))


def sample(cycle, raw, valid=1, failures=0, position=None):
    pos = raw / 65536 + 0.5 if position is None else position
    # cycle raw-hi raw-lo pos-cycle error-info endat-error endat-warning valid fresh alive
    # position age-us phase-us read-failures
    return (f"{cycle} {raw >> 32} {raw & 0xFFFFFFFF} {cycle % 128} 0 0 0 {valid} 1 1 "
            f"{pos:.6f} 100.0 50.0 {failures}\n")


def ctl(cycle, raw):
    return json.dumps({"cycle": cycle, "position_raw": raw, "periods": raw >> 16,
                       "fraction": raw & 0xFFFF, "pos_cycle": cycle % 128, "error_info": 0,
                       "endat_error": 0, "endat_warning": 0, "state": "valid",
                       "fresh": True}) + "\n"


def run(mode, samples, records, *extra):
    with tempfile.TemporaryDirectory() as d:
        s, c = os.path.join(d, "s"), os.path.join(d, "c")
        open(s, "w").write("".join(samples))
        open(c, "w").write("".join(records))
        r = subprocess.run([sys.executable, os.path.join(HERE, "hal_compare.py"), mode, s, c,
                            *extra], capture_output=True, text=True)
        return r.returncode == 0


def main():
    raw = lambda c: 1000000 + 655 * c
    cycles = range(1, 2001)
    good = [sample(c, raw(c)) for c in cycles]
    records = [ctl(c, raw(c)) for c in cycles]
    results = {
        "equal: consistent": run("equal", good, records, "65536", "0.5"),
        "published: consistent": run("published", good, records, "1", "0"),
    }
    bad_value = list(good)
    bad_value[500] = sample(501, raw(501) + 8)
    results["equal: one raw value off"] = not run("equal", bad_value, records, "65536", "0.5")
    bad_pos = list(good)
    bad_pos[700] = sample(701, raw(701), position=raw(701) / 65536 + 0.6)
    results["equal: one scaled position off"] = not run("equal", bad_pos, records, "65536", "0.5")
    torn = list(good)
    torn[900] = sample(901, raw(902))  # this cycle's index with the next cycle's position
    only_hal = [r for i, r in enumerate(records) if i != 900]  # ds1928ctl did not see cycle 901
    results["published: a torn pair (position of the next cycle)"] = \
        not run("published", torn + [sample(901, raw(901))], only_hal, "1", "0")
    gave_up = list(good)
    gave_up[1200] = sample(1200, raw(1200), valid=1, failures=1)  # kept value but claims valid
    gave_up[1201:] = [sample(c, raw(c), failures=1) for c in range(1202, 2001)]
    results["published: a read given up that stays valid"] = \
        not run("published", gave_up, records, "1", "0")
    with tempfile.TemporaryDirectory() as d:
        head = "% time     seconds  usecs/call     calls    errors syscall\n"
        line = lambda n, name: f"100.00    0.1 {28:11d} {n:9d}           {name}\n"
        servo, base = os.path.join(d, "servo"), os.path.join(d, "base")
        open(base, "w").write(head + line(3900, "clock_nanosleep") + line(3900, "total"))
        open(servo, "w").write(head + line(3900, "clock_nanosleep") + line(3900, "total"))
        ok = subprocess.run([sys.executable, os.path.join(HERE, "hal_compare.py"), "syscalls",
                             servo, base], capture_output=True).returncode == 0
        open(servo, "w").write(head + line(3900, "clock_nanosleep") + line(2, "openat") +
                               line(3902, "total"))
        bad = subprocess.run([sys.executable, os.path.join(HERE, "hal_compare.py"), "syscalls",
                              servo, base], capture_output=True).returncode != 0
        results["syscalls: same as the empty thread"] = ok
        results["syscalls: an extra openat"] = bad
    for name, passed in results.items():
        print(("ok:   " if passed else "FAIL: ") + name)
    return 0 if all(results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
