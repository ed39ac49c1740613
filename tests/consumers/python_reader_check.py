#!/usr/bin/env python3
"""The checks of python_reader_test.sh, with the package ds1928 from python/ (PYTHONPATH).

  live SHM SOCKET OUT      wait + read 1000 publications (records to OUT), control socket checks
  compare OUT CTL_JSON     the records equal ds1928ctl's for the same cycles (>= 200 matched)
  abi NAME                 objects of another ABI version / foreign magic / truncated: refused
  restart SHM FLAG         DaemonStopped when the daemon stops, reopen() maps the new one
  timebase SHM             the time base, next_publication() and the isochronous cycles() loop
"""
import json
import os
import struct
import sys
import time

import ds1928

failures = 0


def check(description, condition, detail=""):
    global failures
    print(("ok:   " if condition else "FAIL: ") + description + (f" ({detail})" if detail else ""))
    if not condition:
        failures += 1


def live(shm, socket_path, out):
    r = ds1928.Reader(shm)
    check("Reader maps the daemon's object", r.axis_count >= 1, f"{r.axis_count} axes, period "
          f"{r.cycle_period_ns} ns, generation {r.generation}")
    check("futex wait available (root may write <name>.wait)", r.can_wait)
    d = r.axis(0)
    check("axis(0) is a valid record", d.valid and d.cycle > 0, repr(d))
    seen = r.wait_start()
    woken, cycles = [], []
    with open(out, "w") as f:
        for _ in range(1000):
            seen = r.wait(seen, every=1, timeout=1.0)
            if seen is None:
                break
            woken.append(seen)
            d = r.axis(0)  # may already be a later publication than the one that woke us
            cycles.append(d.cycle)
            rec = {k: getattr(d, k) for k in d.__dataclass_fields__}
            rec.update(fresh=d.fresh, new_position=d.new_position)
            f.write(json.dumps(rec) + "\n")
    check("wait() returned 1000 times with increasing cycles, each read at or after its cycle",
          len(woken) == 1000 and all(b > a for a, b in zip(woken, woken[1:])) and
          all(c >= w for c, w in zip(cycles, woken)),
          f"{len(woken)} wake-ups, cycles {woken[:1]}..{woken[-1:]}")
    # every=4: each return is the last published cycle, and a multiple of 4 was published since
    # the previous return (the reader may be late, so the cycle itself need not be one).
    start = r.wait_start()
    every4 = [start]
    for _ in range(20):
        every4.append(r.wait(every4[-1], every=4, timeout=1.0))
    check("wait(every=4) returns only after a multiple of 4 was published",
          None not in every4 and all(b // 4 > a // 4 for a, b in zip(every4, every4[1:])),
          f"{every4[:8]}...")
    r.close()

    with ds1928.Control(socket_path, timeout=20) as c:
        status = c.status()
        check("control: status ok", status.get("ok") is True, str(status)[:100])
        ident = c.endat_ident(axis=0)
        bits = ident.get("identification", {}).get("position_bits")
        check("control: endat-ident gives the encoder's position bits", bits == 37, f"{bits}")
        try:
            c.request("no-such-command")
            check("control: unknown command raises ControlError", False)
        except ds1928.ControlError as e:
            check("control: unknown command raises ControlError", e.code == "unknown_command",
                  e.code)
        try:
            c.endat_read_param(mrs="0xA1", param=13, axis=99)
            check("control: axis 99 raises bad_argument", False)
        except ds1928.ControlError as e:
            check("control: axis 99 raises bad_argument", e.code == "bad_argument", e.message)


def compare(py_path, ctl_path):
    def load(path):
        out = {}
        with open(path) as f:
            for line in f:
                if line.startswith("{"):
                    rec = json.loads(line)
                    if "cycle" in rec:
                        out[rec["cycle"]] = rec
        return out

    py, ctl = load(py_path), load(ctl_path)
    fields = ["position_raw", "periods", "fraction", "position_sdc", "pos_time_ns", "pos_time_raw",
              "time_source", "pos_cycle", "error_info", "endat_error", "endat_warning",
              "publish_ns", "state", "fresh", "new_position"]
    matched, diffs = 0, []
    for cycle, p in py.items():
        c = ctl.get(cycle)
        if c is None:
            continue
        matched += 1
        diffs += [f"cycle {cycle} {k}: {p[k]} != {c[k]}" for k in fields if p[k] != c[k]]
    check("Python's records equal ds1928ctl's for the same cycles",
          matched >= 200 and not diffs, f"{matched} cycles matched, {len(diffs)} differences "
          f"{diffs[:3]}")


def abi(name):
    path = "/dev/shm" + name
    magic = ds1928.shm.SHM_MAGIC
    cases = [  # (case, magic, abi_version, axis_count, what the message must say)
        ("another ABI version", magic, 2, 1, "ABI version 2, this reader knows version 1"),
        ("a foreign object", 0x1122334455667788, 1, 1, "not ds1928d shared memory"),
        ("more axes than the object holds", magic, 1, 1000, "do not fit ABI version 1"),
    ]
    for case, m, version, axes, message in cases:
        header = bytearray(4096)
        struct.pack_into("<QIIII", header, 0, m, version, 128, 128, axes)
        with open(path, "wb") as f:
            f.write(header)
        try:
            ds1928.Reader(name)
            check(f"{case}: refused", False)
        except ds1928.AbiMismatch as e:
            check(f"{case}: refused with AbiMismatch", message in str(e), str(e))
        finally:
            os.unlink(path)
    try:
        ds1928.Reader(name)
        check("missing object: FileNotFoundError", False)
    except FileNotFoundError as e:
        check("missing object: FileNotFoundError naming the daemon", "is ds1928d running" in str(e),
              str(e))


def restart(shm, flag):
    r = ds1928.Reader(shm)
    first = r.generation
    seen = r.wait_start()
    open(flag, "w").close()  # the shell stops the daemon now
    stopped = False
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        try:
            seen = r.wait(seen, timeout=0.2)
        except ds1928.DaemonStopped:
            stopped = True
            break
    check("wait() raises DaemonStopped when the daemon stops", stopped)
    check("daemon_alive() false after the stop", not r.daemon_alive())
    reopened = False
    while time.monotonic() < deadline and not reopened:
        reopened = r.reopen()
        time.sleep(0.05)
    check("reopen() maps the restarted daemon (new generation)",
          reopened and r.generation != first, f"{first} -> {r.generation}")
    if reopened:
        seen = r.wait(r.wait_start(), timeout=5)
        check("the new generation publishes", seen is not None and r.axis(0).cycle >= seen)


def timebase(shm):
    r = ds1928.Reader(shm)
    check("the daemon publishes the time base (features bit 0)", r.has_timebase, f"{r.features}")
    tb = r.timebase()
    check("time base: t0 set, the period, a measured publication offset, kind monotonic",
          tb is not None and tb.t0_ns > 0 and tb.period_ns == r.cycle_period_ns and
          0 < tb.publish_offset_p50_ns <= tb.publish_offset_p99_ns <= tb.publish_offset_max_ns
          and tb.kind == "monotonic", repr(tb))
    before = time.clock_gettime_ns(time.CLOCK_MONOTONIC)
    at, cycle = r.next_publication(every=3)
    tb2 = r.timebase()  # a measurement window may close in between: either figure is right
    check("next_publication(every=3): a multiple of 3 on the timeline, after now",
          cycle % 3 == 0 and at > before and
          at in (tb.t0_ns + cycle * tb.period_ns + p.publish_offset_p99_ns for p in (tb, tb2)),
          f"{at} {cycle}")
    acq, acq_max = r.acq_to_publish(0)
    check("axis 0's acquisition-to-publication time is measured", 0 < acq_max, f"{acq} {acq_max}")
    # 300 passes of the isochronous loop at every 2nd cycle, 100 µs after the publication.
    passes, current = [], 0
    for sample in r.cycles(every=2, offset_us=100):
        passes.append(sample)
        current += sample.axes[0].cycle >= sample.cycle
        if len(passes) == 300:
            break
    cycles = [p.cycle for p in passes]
    check("cycles(every=2): increasing multiples of 2", all(c % 2 == 0 for c in cycles) and
          all(b > a for a, b in zip(cycles, cycles[1:])), f"{cycles[:3]}..{cycles[-1:]}")
    check("cycles(): woke at or after the publication + 100 µs",
          all(p.woke_ns >= p.publication_ns + 100_000 for p in passes))
    # The pass reads the cycle it was timed for (or a later one, when the reader itself woke
    # late) in almost every pass: an older record means a publication later than its p99 +
    # 100 µs, which is rare.
    check("cycles(): the timed cycle's record (or a later one) was read in >= 90 % of the passes",
          current >= 270, f"{current} of 300")

def main():
    mode, args = sys.argv[1], sys.argv[2:]
    {"live": live, "compare": compare, "abi": abi, "restart": restart,
     "timebase": timebase}[mode](*args)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
