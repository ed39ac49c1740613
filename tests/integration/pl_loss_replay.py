#!/usr/bin/env python3
"""Replays the MN's loss-of-PRes counter from the wire, to tell a CN that answered late from an MN
that counted wrongly.

  pl_loss_replay.py NODE PRES_TIMEOUT_US THRESHOLD CN_END.pcapng MN_END.pcapng

CN_END: capture on the CN's interface (the MN's SoC and PReq as the CN receives them); MN_END:
capture on the MN's interface (the CN's PRes as the MN receives them). With PACKET_QDISC_BYPASS a
sender's own frames do not show on its interface, hence two captures; one machine, one clock.

Per cycle (SoC to SoC, EPSG DS 301 DLL error counter, docs/powerlink.md §DLL error counters): a
PReq to NODE whose PRes reached the MN end within PRES_TIMEOUT_US is good (−1, not below 0), one
without is an error (+8); a cycle without a PReq to NODE is good; at THRESHOLD the counter fires
and restarts. The two captures' stamps and the MN's own clock differ by microseconds, so a PRes
within TOLERANCE_US of the timeout counts both ways: `upper` counts it late, `lower` in time.

Prints one line: "fired_upper=N fired_lower=N cycles=N late=N missing=N near=N peak=N", where late
= PRes after the timeout, missing = none before the next PReq, near = within the tolerance, peak =
the highest counter reached (upper).
"""
import bisect
import subprocess
import sys

TOLERANCE_US = 20


def frames(path):
    out = subprocess.run(
        ["tshark", "--disable-protocol", "opensafety", "-n", "-r", path, "-T", "fields",
         "-e", "frame.time_epoch", "-e", "epl.mtyp", "-e", "epl.src", "-e", "epl.dest", "-Y", "epl"],
        capture_output=True, text=True, check=True).stdout
    rows = []
    for line in out.splitlines():
        parts = line.split("\t")
        if len(parts) < 4 or not parts[1]:
            continue
        rows.append((float(parts[0]), int(parts[1], 0), int(parts[2] or 0), int(parts[3] or 0)))
    return rows


def replay(node, timeout_s, threshold, socs, preqs, pres, tolerance_s):
    """Fires of the counter (lower, upper bound) and the counts behind them."""
    fired = {"upper": 0, "lower": 0}
    counter = {"upper": 0, "lower": 0}
    stats = {"cycles": 0, "late": 0, "missing": 0, "near": 0, "peak": 0}
    for i, soc in enumerate(socs):
        end = socs[i + 1] if i + 1 < len(socs) else float("inf")
        stats["cycles"] += 1
        k = bisect.bisect_left(preqs, soc)
        verdict = {"upper": False, "lower": False}  # True: an error this cycle
        if k < len(preqs) and preqs[k] < end:
            preq = preqs[k]
            nxt = preqs[k + 1] if k + 1 < len(preqs) else float("inf")
            j = bisect.bisect_left(pres, preq)
            answer = pres[j] if j < len(pres) and pres[j] < nxt else None
            if answer is None:
                stats["missing"] += 1
                verdict = {"upper": True, "lower": True}
            else:
                delay = answer - preq
                if delay > timeout_s + tolerance_s:
                    stats["late"] += 1
                    verdict = {"upper": True, "lower": True}
                elif delay > timeout_s - tolerance_s:
                    stats["near"] += 1
                    verdict = {"upper": True, "lower": False}
        for bound in ("upper", "lower"):
            if verdict[bound]:
                counter[bound] += 8
            elif counter[bound] > 0:
                counter[bound] -= 1
            if bound == "upper":
                stats["peak"] = max(stats["peak"], counter[bound])
            if threshold > 0 and counter[bound] >= threshold:
                fired[bound] += 1
                counter[bound] = 0
    return fired, stats


def main():
    if len(sys.argv) != 6:
        sys.exit(__doc__.split("\n\n")[1])
    node, timeout_us, threshold = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
    cn_end, mn_end = frames(sys.argv[4]), frames(sys.argv[5])
    socs = sorted(t for t, mtyp, _src, _dst in cn_end if mtyp == 1)
    preqs = sorted(t for t, mtyp, _src, dst in cn_end if mtyp == 3 and dst == node)
    pres = sorted(t for t, mtyp, src, _dst in mn_end if mtyp == 4 and src == node)
    if not socs or not preqs:
        sys.exit("no SoC or no PReq to node %d in %s" % (node, sys.argv[4]))
    fired, stats = replay(node, timeout_us / 1e6, threshold, socs, preqs, pres,
                          TOLERANCE_US / 1e6)
    print("fired_upper=%d fired_lower=%d cycles=%d late=%d missing=%d near=%d peak=%d" % (
        fired["upper"], fired["lower"], stats["cycles"], stats["late"], stats["missing"],
        stats["near"], stats["peak"]))


if __name__ == "__main__":
    main()
