#!/usr/bin/env python3
"""Explains each reset of a mixed PollResponse Chaining hold from the wire.

  pl_prc_resets.py [--pres-timeout-us N] FRAMES.tsv THRESHOLD SOC_LOSS_MS SLOT_US [ASYNC_US [STALLS]]

FRAMES.tsv: both veth ends' POWERLINK frames merged by time (one clock: one machine), columns
time, MessageType, source, destination, SoA service, ASnd service, NMTCommandId, the NMT state
of a PRes, of an IdentResponse, of a StatusResponse, the SoA's RequestedServiceTarget.
Each NMTResetNode the MN sent to a CN (ASnd NMTCommand 0x28) is a reset. A reset is explained
by the wire when, before it and since the node's previous reset (checked in this order),
  - the node's PRes was missing from its cycles often enough for the MN's loss-of-PRes counter
    (DS 301: +8 per cycle without the node's PRes, -1 per cycle with it) to reach THRESHOLD:
    replayed per cycle from the wire, a PRC node's PRes counting when it came within SLOT_US of
    the cycle's PResMN (the MN's PRC slot: later is outside its slot, lost), a PReq/PRes node's
    when it came after its PReq within the MN's PResTimeout (--pres-timeout-us; without it
    SLOT_US): the MN counts a later PRes lost (EPSG DS 301). The two captures' stamps and the
    MN's clock differ by microseconds, so with --pres-timeout-us a PRes within TOLERANCE_US
    before the timeout counts late too (the upper bound: a reset this replay cannot explain, the
    MN counted wrongly);
  - or a SyncRequest to the node (PollResponse Chaining set-up) got no SyncResponse within
    ASYNC_US (the MN's AsyncSlotTimeout, default 100 µs; the MN resets a PRC node at the second
    miss),
  - or the node reported a state the MN resets it for: another than OPERATIONAL after an
    OPERATIONAL one (it fell back), or READY_TO_OPERATE/OPERATIONAL in an Ident- or
    StatusResponse while being booted (it did not take an earlier NMTResetNode),
  - or the MN's SoCs stopped for longer than the simulated CN's loss-of-SoC limit (SOC_LOSS_MS),
    the gap ending at most GAP_WINDOW_S (2 s) before the reset,
  - or the node was being booted for longer than a boot step may take (BOOT_STEP_S, 5 s: its
    answers in the asynchronous slots came late or not; not OPERATIONAL since its last reset).
STALLS (bench/cycle/host_stall_probe's output: CPU START END LATE_MS per line) says whose a SoC gap
was: the host's when a CPU's probe thread, at SCHED_FIFO 99, was stopped for all of the gap but
HOST_SLACK_MS (its own period, the MN's cycle and wake-up) — the host did not run that vCPU, and
the MN on it could not send. A reset is `host_stalled` when such a gap ended at most GAP_WINDOW_S before
it, whatever cause explains it (the CN's fall-back, the MN's threshold).
Prints one line: resets, explained by each cause, unexplained, host_stalled, the SoC gaps over
SOC_LOSS_MS that the host caused (gaps_host), the longest SoC gap (ms), the SoC
gaps longer than SOC_LOSS_MS, and per node the cycles without its PRes on the wire.
"""
import sys

RESET_NODE = 0x28
BOOT_STEP_S = 5.0
GAP_WINDOW_S = 2.0
# A CPU's stop seen by the probe is shorter than the SoC gap it caused by up to the probe's own
# period (the stop began before its missed wake-up), the MN's cycle (after it the MN sends at its
# next cycle start) and a wake-up: 1 + 1 + 0.5 ms at the hold's 1 ms.
HOST_SLACK_MS = 2.5
TOLERANCE_US = 20
OPERATIONAL = 0xFD


def num(v):
    return int(v, 0) if v else None


def main():
    argv = sys.argv[1:]
    pres_timeout_s = None  # SLOT_US
    if argv[:1] == ["--pres-timeout-us"]:
        pres_timeout_s = (float(argv[1]) - TOLERANCE_US) / 1e6
        argv = argv[2:]
    path, threshold, soc_loss_ms = argv[0], int(argv[1]), float(argv[2])
    slot_s = float(argv[3]) / 1e6
    if pres_timeout_s is None:
        pres_timeout_s = slot_s
    async_s = float(argv[4] if len(argv) > 4 else 100) / 1e6
    stalls = []  # (start, end) of each CPU's stop seen by the probe
    if len(argv) > 5:
        for line in open(argv[5]):
            f = line.split()
            if len(f) >= 3:
                stalls.append((float(f[1]), float(f[2])))
    sync_missed = {}
    sync_open = {}
    rows = []
    for line in open(path):
        f = (line.rstrip("\n").split("\t") + [""] * 11)[:11]
        if not f[1]:
            continue
        state = f[7] or f[8] or f[9]
        # A SoA names its invited node in RequestedServiceTarget: kept as its destination.
        dst = num(f[10]) if num(f[1]) == 5 and f[10] else num(f[3])
        rows.append((float(f[0]), num(f[1]), num(f[2]), dst, num(f[4]), num(f[5]),
                     num(f[6]), num(state)))
    counter, fired_at, missing = {}, {}, {}
    cycle_seen, polled, answered = set(), {}, set()
    gap_at, last_soc, max_gap, long_gaps = [], None, 0.0, 0
    host_gap_at = []  # the ends of the gaps a stopped CPU accounts for
    not_op_at = {}
    was_op = set()
    resets = []

    def close_cycle():
        for node in polled:
            lost = node not in answered
            c = counter.get(node, 0)
            if lost:
                missing[node] = missing.get(node, 0) + 1
                c += 8
            elif c > 0:
                c -= 1
            if threshold and c >= threshold:
                fired_at.setdefault(node, []).append(last_soc)
                c = 0
            counter[node] = c

    pres_mn_seen = False
    pres_mn_t = 0.0
    preq_t = {}
    prc_members = set()  # nodes that answered a PResMN since their last reset
    for t, mtyp, src, dst, soa_svid, asnd_svid, cid, stat in rows:
        if src is not None and src != 240 and stat is not None and mtyp in (4, 6):
            if stat == OPERATIONAL and mtyp == 4:
                was_op.add(src)
            elif (src in was_op and stat != OPERATIONAL) or (
                    mtyp == 6 and stat in (0x6D, OPERATIONAL) and src not in was_op):
                not_op_at.setdefault(src, []).append(t)
        if mtyp == 5 and soa_svid == 6 and dst is not None:
            for n, t0 in list(sync_open.items()):
                sync_missed.setdefault(n, []).append(t0)
            sync_open = {dst: t}
        elif mtyp == 6 and asnd_svid == 6 and src in sync_open:
            if t - sync_open.pop(src) > async_s:
                sync_missed.setdefault(src, []).append(t)
        if mtyp == 1:  # SoC: the previous cycle is complete
            if last_soc is not None:
                close_cycle()
                gap = (t - last_soc) * 1000
                max_gap = max(max_gap, gap)
                if gap > soc_loss_ms:
                    long_gaps += 1
                    gap_at.append(t)
                    a, b = last_soc, t
                    if any(min(b, e) - max(a, st) >= (b - a) - HOST_SLACK_MS / 1000
                           for st, e in stalls):
                        host_gap_at.append(t)
            last_soc, polled, answered, pres_mn_seen = t, {}, set(), False
        elif mtyp == 4 and src == 240:
            pres_mn_seen = True
            pres_mn_t = t
            for n in prc_members:
                polled[n] = "prc"  # polled by the PResMN: missing if its PRes does not come
        elif mtyp == 3 and dst is not None:
            polled[dst] = "preq"
            preq_t[dst] = t
        elif mtyp == 4 and src is not None and last_soc is not None:
            if src not in polled and pres_mn_seen:
                polled[src] = "prc"  # a PRC node answers the PResMN without a PReq
                prc_members.add(src)
            if polled.get(src) == "prc":
                in_time = t - pres_mn_t <= slot_s
            else:
                in_time = t - preq_t.get(src, 0.0) <= pres_timeout_s
            if in_time:
                answered.add(src)
        elif mtyp == 6 and asnd_svid == 4 and cid == RESET_NODE and dst is not None:
            resets.append((t, dst))
            prc_members.discard(dst)
            was_op.discard(dst)
            # (the MN's loss counter runs on across a reset: it restarts at 0 only when it fires)
    explained = {"soc_gap": 0, "pres_missing": 0, "sync_missing": 0, "not_operational": 0,
                 "boot_timeout": 0}
    op_times = {}
    for t, mtyp, src, dst, soa_svid, asnd_svid, cid, stat in rows:
        if mtyp == 4 and stat == OPERATIONAL and src is not None:
            op_times.setdefault(src, []).append(t)
    unexplained = []
    prev = {}
    first_t = rows[0][0] if rows else 0.0
    host_stalled = 0
    for t, node in resets:
        since = prev.get(node, 0.0)
        prev[node] = t
        if any(max(since, t - GAP_WINDOW_S) < g <= t for g in host_gap_at):
            host_stalled += 1
        # The direct causes first (the MN's counter replayed, the node's own report), a SoC gap
        # only when it ended shortly before the reset (GAP_WINDOW_S): the CN's fall-back or the
        # MN's threshold follow a gap within cycles, not minutes.
        if any(since < f <= t for f in fired_at.get(node, [])):
            explained["pres_missing"] += 1
        elif any(since < x <= t for x in sync_missed.get(node, [])):
            explained["sync_missing"] += 1
        elif any(since < x <= t for x in not_op_at.get(node, [])):
            explained["not_operational"] += 1
        elif any(max(since, t - GAP_WINDOW_S) < g <= t for g in gap_at):
            explained["soc_gap"] += 1
        elif t - max(since, first_t) >= BOOT_STEP_S and not any(
                since < x <= t for x in op_times.get(node, [])):
            explained["boot_timeout"] += 1
        else:
            unexplained.append("node %d at %.3f" % (node, t))
    print("resets=%d soc_gap=%d pres_missing=%d sync_missing=%d not_operational=%d "
          "boot_timeout=%d unexplained=%d host_stalled=%d "
          "max_soc_gap_ms=%.1f soc_gaps_over_limit=%d gaps_host=%d cycles_without_pres=%s%s" % (
              len(resets), explained["soc_gap"], explained["pres_missing"],
              explained["sync_missing"],
              explained["not_operational"], explained["boot_timeout"], len(unexplained),
              host_stalled, max_gap, long_gaps, len(host_gap_at),
              ",".join("%d:%d" % kv for kv in sorted(missing.items())),
              (" first_unexplained=" + unexplained[0]) if unexplained else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
