#!/usr/bin/env python3
"""Cycle timing seen on the wire, from captures at both ends of the MN–CN veth pair.

  pl_capture_stats.py PERIOD_US CN_END.pcapng MN_END.pcapng

CN_END: capture on the CN's interface (the MN's SoC/PReq/SoA as the CN receives them);
MN_END: capture on the MN's interface (the CN's PRes as the MN receives them). With
PACKET_QDISC_BYPASS a sender's own frames do not show on its interface, hence two captures;
both carry the same clock (one machine).
Prints one line: SoC period deviation, SoC→PReq (first PReq of the cycle) and PReq→PRes
(per polled CN) as p50/p99/max in µs, and the count of PRes later than 1 ms; then the SoC→SoC
period min/max (µs), the PReqs left without a PRes before the next PReq to that CN, the
NMTResetNode commands the MN sent (ASnd NMTCommand 0x28), and the PRes that carry another NMT state
than OPERATIONAL after a CN's first OPERATIONAL PRes.
"""
import subprocess
import sys


def frames(path):
    out = subprocess.run(
        ["tshark", "-n", "-r", path, "-T", "fields", "-e", "frame.time_epoch", "-e", "epl.mtyp",
         "-e", "epl.src", "-e", "epl.dest", "-e", "epl.asnd.nmtcommand.cid", "-e", "epl.pres.stat",
         "-Y", "epl"],
        capture_output=True, text=True, check=True).stdout
    rows = []
    extra = []
    for line in out.splitlines():
        parts = line.split("\t")
        if len(parts) < 4 or not parts[1]:
            continue
        rows.append((float(parts[0]), int(parts[1], 0), int(parts[2] or 0), int(parts[3] or 0)))
        extra.append((int(parts[4], 0) if len(parts) > 4 and parts[4] else None,
                      int(parts[5], 0) if len(parts) > 5 and parts[5] else None))
    return rows, extra


def quant(values):
    if not values:
        return "-/-/-"
    v = sorted(values)
    def q(p):
        return v[min(len(v) - 1, int(p * len(v)))]
    return "%.0f/%.0f/%.0f" % (q(0.5), q(0.99), v[-1])


def main():
    period_us = float(sys.argv[1])
    cn_end, cn_extra = frames(sys.argv[2])
    mn_end, mn_extra = frames(sys.argv[3])
    soc = [t for t, m, s, d in cn_end if m == 1]
    jitter = [abs((b - a) * 1e6 - period_us) for a, b in zip(soc, soc[1:])]
    # SoC→first PReq of the same cycle.
    soc_preq = []
    last_soc = None
    for t, m, s, d in cn_end:
        if m == 1:
            last_soc = t
        elif m == 3 and last_soc is not None:
            soc_preq.append((t - last_soc) * 1e6)
            last_soc = None
    # PReq (as the CN got it) → PRes of that CN (as the MN got it), before the next PReq to it.
    events = sorted([(t, "preq", d) for t, m, s, d in cn_end if m == 3] +
                    [(t, "pres", s) for t, m, s, d in mn_end if m == 4])
    pending = {}
    latency = []
    unanswered = 0
    for t, kind, node in events:
        if kind == "preq":
            if node in pending:
                unanswered += 1
            pending[node] = t
        elif node in pending:
            latency.append((t - pending.pop(node)) * 1e6)
    late = sum(1 for x in latency if x > 1000)
    periods = [(b - a) * 1e6 for a, b in zip(soc, soc[1:])]
    resets = sum(1 for (t, m, s, d), (cid, _) in zip(cn_end, cn_extra)
                 if m == 6 and cid == 0x28)
    operational = set()
    not_op = 0
    for (t, m, s, d), (_, stat) in zip(mn_end, mn_extra):
        if m != 4 or stat is None:
            continue
        if stat == 0xFD:
            operational.add(s)
        elif s in operational:
            not_op += 1
    print("WIRE soc_jitter_us=%s soc_to_preq_us=%s preq_to_pres_us=%s cycles=%d pres=%d "
          "pres_over_1ms=%d soc_period_us=%s preq_unanswered=%d reset_node=%d "
          "pres_not_operational=%d" % (
              quant(jitter), quant(soc_preq), quant(latency), len(soc), len(latency), late,
              "%.0f/%.0f" % (min(periods), max(periods)) if periods else "-/-", unanswered,
              resets, not_op))


if __name__ == "__main__":
    main()
