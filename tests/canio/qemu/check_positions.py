#!/usr/bin/env python3
"""Checks the samples ds1928d published for one axis over CAN-I/O.

Reads `ds1928ctl --json position --axis N --follow --count K` lines on stdin (one JSON object
per publication) and checks what must hold on every sample whatever the machine's speed:

  - a fresh sample is "valid", its time source is the master's reception time ("rx_timestamp"),
    its stamp is set, not later than its publication and not earlier than --since-ns, and the
    stamps of fresh samples never go backwards;
  - positions move (the simulated encoder turns at constant velocity), never backwards;
  - at least --min-fresh samples are fresh.

With --answer-log FILE (ds1928-sim canio --answer-log: "sync slot position pos_cycle" per
answer) every fresh sample must be one the node sent as a whole: its position and its PosCycle
from the same answer — a sample combining two SYNCs ("torn") fails.

Nothing about timing is asserted (the QEMU guest is TCG-emulated). Exit 0 when everything held,
1 otherwise, with one line per problem. --expect-no-fresh inverts the purpose: the daemon was
given a wrong identifier, so no sample may be fresh or valid (exit 0 when none is; the positive
check then necessarily fails on --min-fresh, which must be at least 1).
"""
import argparse
import json
import sys


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--min-fresh", type=int, default=20)
    ap.add_argument("--since-ns", type=int, default=0,
                    help="CLOCK_MONOTONIC before the daemon started: no stamp may be earlier")
    ap.add_argument("--expect-no-fresh", action="store_true")
    ap.add_argument("--answer-log", help="the node's answers: no fresh sample may be torn")
    args = ap.parse_args()

    samples = []
    for n, line in enumerate(sys.stdin, 1):
        line = line.strip()
        if not line:
            continue
        try:
            s = json.loads(line)
        except json.JSONDecodeError as e:
            print(f"FAIL: line {n} is not JSON ({e}): {line[:120]}")
            return 1
        if "position_raw" in s:  # events (e.g. the daemon going away) are other objects
            samples.append(s)

    if not samples:
        print("FAIL: no publication read from shared memory")
        return 1
    fresh = [s for s in samples if s["fresh"]]
    states = {}
    for s in samples:
        states[s["state"]] = states.get(s["state"], 0) + 1
    summary = (f"{len(samples)} publications, {len(fresh)} fresh, states {states}, "
               f"cycles {samples[0]['cycle']}..{samples[-1]['cycle']}")

    if args.expect_no_fresh:
        valid = states.get("valid", 0)
        if fresh or valid:
            print(f"FAIL: expected no fresh or valid sample, got {summary}")
            return 1
        print(f"ok: no fresh sample: {summary}")
        print(f"ok: and the position check fails: only 0 fresh samples, expected at least "
              f"{args.min_fresh}")
        return 0

    problems = []
    last_stamp = None
    last_raw = None
    moves = 0
    for s in fresh:
        where = f"cycle {s['cycle']}"
        if s["state"] != "valid":
            problems.append(f"{where}: fresh but state {s['state']}")
        if s["time_source"] != "rx_timestamp":
            problems.append(f"{where}: time source {s['time_source']}, expected rx_timestamp")
        t, pub = s["pos_time_ns"], s["publish_ns"]
        if t <= 0:
            problems.append(f"{where}: no receive time stamp")
        elif t > pub:
            problems.append(f"{where}: stamp {t} later than its publication {pub}")
        elif t < args.since_ns:
            problems.append(f"{where}: stamp {t} before the daemon started ({args.since_ns})")
        if last_stamp is not None and t < last_stamp:
            problems.append(f"{where}: stamp {t} earlier than the previous fresh one {last_stamp}")
        last_stamp = t
        raw = s["position_raw"]
        if last_raw is not None:
            # Constant positive velocity: the 64-bit position only grows (mod 2^64).
            step = (raw - last_raw) % (1 << 64)
            if step >= (1 << 63):
                problems.append(f"{where}: position went backwards ({last_raw:#x} -> {raw:#x})")
            elif step:
                moves += 1
        last_raw = raw
    torn = 0
    if args.answer_log:
        sent = {}
        with open(args.answer_log) as f:
            for line in f:
                parts = line.split()
                if len(parts) == 4:
                    # The simulated encoder moves at constant velocity: a position is sent once.
                    sent.setdefault(int(parts[2]), set()).add(int(parts[3]))
        for s in fresh:
            pcs = sent.get(s["position_raw"])
            if pcs is None:
                problems.append(f"cycle {s['cycle']}: position {s['position_raw']:#x} "
                                f"was never sent by the node")
            elif s["pos_cycle"] not in pcs:
                torn += 1
                problems.append(f"cycle {s['cycle']}: TORN: position {s['position_raw']:#x} "
                                f"with PosCycle {s['pos_cycle']}, the node sent it with {sorted(pcs)}")
        summary += f", {len(sent)} answers logged, torn {torn}"
    if len(fresh) < args.min_fresh:
        problems.append(f"only {len(fresh)} fresh samples, expected at least {args.min_fresh}")
    if fresh and moves == 0:
        problems.append("the position never moved")
    for p in problems[:20]:
        print(f"FAIL: {p}")
    if problems:
        print(f"     ({len(problems)} problems; {summary})")
        return 1
    first, last = fresh[0], fresh[-1]
    print(f"ok: {summary}; position {first['periods']} -> {last['periods']} periods "
          f"({moves} moves), every fresh sample valid with an rx_timestamp stamp "
          f"<= its publication, stamps monotonic")
    return 0


if __name__ == "__main__":
    sys.exit(main())
