#!/usr/bin/env python3
"""Checks of linuxcnc_hal_test.sh on what it recorded.

  hal_compare.py equal SAMPLES CTL_JSON SCALE OFFSET
      every sampled servo period whose bus cycle ds1928ctl also printed shows that record's values
      (raw position, scaled position, PosCycle, ErrorInfo, EnDat words, validity, freshness);
      at least 300 cycles matched.
  hal_compare.py published SAMPLES CTL_JSON SCALE OFFSET
      torn-read stress: one raw position per bus cycle across all samples, equal to ds1928ctl's
      where both saw the cycle, nondecreasing with the cycle (constant positive velocity).
  hal_compare.py syscalls SERVO_STRACE BASE_STRACE
      the system calls of the servo thread (strace -c) are a subset of those of an empty thread.

SAMPLES: halsampler lines of the pins of linuxcnc_hal_test.sh's `pins` list, in that order.
"""
import json
import sys

FIELDS = ["cycle", "raw_hi", "raw_lo", "pos_cycle", "error_info", "endat_error", "endat_warning",
          "valid", "fresh", "alive", "position", "age_us", "phase_us", "failures"]


def load_samples(path):
    rows = []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) != len(FIELDS):
                continue
            row = {}
            for name, text in zip(FIELDS, parts):
                row[name] = float(text) if name in ("position", "age_us", "phase_us") else int(text)
            row["raw"] = (row["raw_hi"] << 32) | row["raw_lo"]
            rows.append(row)
    return rows


def load_ctl(path):
    records = {}
    with open(path) as f:
        for line in f:
            line = line.strip()
            if not line.startswith("{"):
                continue
            r = json.loads(line)
            if "cycle" in r:
                records[r["cycle"] & 0xFFFFFFFF] = r
    return records


def quantiles(values):
    s = sorted(values)
    if not s:
        return "none"
    pick = lambda q: s[min(len(s) - 1, int(q * len(s)))]
    return f"p50 {pick(0.5):.1f} p99 {pick(0.99):.1f} max {s[-1]:.1f}"


def equal(samples_path, ctl_path, scale, offset):
    samples, ctl = load_samples(samples_path), load_ctl(ctl_path)
    matched, errors = 0, []
    for i, s in enumerate(samples):
        r = ctl.get(s["cycle"])
        if r is None or not s["alive"]:
            continue
        if i > 0 and s["failures"] != samples[i - 1]["failures"]:
            continue  # a read given up: the last value, invalid (checked by `published`)
        matched += 1
        expect_pos = (r["periods"] * 65536 + r["fraction"]) / scale + offset
        checks = [
            ("raw", s["raw"], r["position_raw"]),
            ("pos-cycle", s["pos_cycle"], r["pos_cycle"]),
            ("error-info", s["error_info"], r["error_info"]),
            ("endat-error", s["endat_error"], r["endat_error"]),
            ("endat-warning", s["endat_warning"], r["endat_warning"]),
            ("valid", s["valid"], int(r["state"] == "valid")),
            ("fresh", s["fresh"], int(r["fresh"])),
        ]
        for name, got, want in checks:
            if got != want:
                errors.append(f"cycle {s['cycle']}: {name} {got} != ds1928ctl {want}")
        # halsampler prints floats with 6 decimals.
        if abs(s["position"] - expect_pos) > 1e-5 + 1e-12 * abs(expect_pos):
            errors.append(f"cycle {s['cycle']}: position {s['position']} != {expect_pos}")
    print(f"{len(samples)} servo periods sampled, {len(ctl)} bus cycles from ds1928ctl, "
          f"{matched} matched by cycle, {len(errors)} differences")
    print("age-us at the servo read:", quantiles([s["age_us"] for s in samples if s["alive"]]))
    print("phase-us:", quantiles([s["phase_us"] for s in samples if s["alive"]]))
    for e in errors[:10]:
        print("  ", e)
    return not errors and matched >= 300


def published(samples_path, ctl_path, scale, offset):
    del scale, offset
    samples, ctl = load_samples(samples_path), load_ctl(ctl_path)
    by_cycle, errors, matched = {}, [], 0
    for s in samples:
        if not s["alive"]:
            continue
        seen = by_cycle.setdefault(s["cycle"], s["raw"])
        if seen != s["raw"]:
            errors.append(f"cycle {s['cycle']}: two positions {seen:#x} and {s['raw']:#x}")
        r = ctl.get(s["cycle"])
        if r is not None:
            matched += 1
            if r["position_raw"] != s["raw"]:
                errors.append(f"cycle {s['cycle']}: {s['raw']:#x} != ds1928ctl "
                              f"{r['position_raw']:#x}")
    gave_up = 0
    for prev, s in zip(samples, samples[1:]):
        if s["failures"] == prev["failures"]:
            continue
        gave_up += 1
        if s["valid"] or s["raw"] != prev["raw"] or s["cycle"] != prev["cycle"]:
            errors.append(f"read given up after cycle {prev['cycle']}: valid {s['valid']}, "
                          f"raw {s['raw']:#x} (before {prev['raw']:#x}), cycle {s['cycle']}")
    last = None
    for cycle in sorted(by_cycle):
        if last is not None and by_cycle[cycle] < by_cycle[last]:
            errors.append(f"cycle {cycle}: position {by_cycle[cycle]:#x} below cycle {last}'s "
                          f"{by_cycle[last]:#x}")
        last = cycle
    print(f"{len(samples)} reads sampled, {len(by_cycle)} distinct bus cycles, {matched} reads "
          f"of a cycle ds1928ctl printed too, {gave_up} reads given up, "
          f"{len(errors)} inconsistencies")
    for e in errors[:10]:
        print("  ", e)
    return not errors and matched >= 100 and len(by_cycle) >= 1000


def strace_calls(path):
    calls = {}
    with open(path) as f:
        for line in f:
            parts = line.split()
            if len(parts) >= 5 and parts[3].isdigit() and parts[-1] != "total":
                calls[parts[-1]] = int(parts[3])
    return calls


def syscalls(servo_path, base_path):
    servo, base = strace_calls(servo_path), strace_calls(base_path)
    extra = sorted(set(servo) - set(base))
    print(f"servo thread: {servo}; empty thread: {base}; only in the servo thread: {extra}")
    return bool(servo) and not extra


def main():
    mode = sys.argv[1]
    if mode == "syscalls":
        ok = syscalls(sys.argv[2], sys.argv[3])
    else:
        fn = {"equal": equal, "published": published}[mode]
        ok = fn(sys.argv[2], sys.argv[3], float(sys.argv[4]), float(sys.argv[5]))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
