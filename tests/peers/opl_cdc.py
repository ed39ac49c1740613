#!/usr/bin/env python3
"""Copies openPOWERLINK's demo concise DCF (mnobd.cdc) with another cycle time (and PRC or
multiplexing).

  opl_cdc.py IN.cdc OUT.cdc [--cycle-us N] [--prc-node N ...] [--mux-node N ... [--mux-count C]]
             [--list]

The demo's CDC (openCONFIGURATOR project Demo_3CN) sets NMT_CycleLen_U32 (0x1006) to 50 ms, for
the MN and, inside each CN's concise DCF (0x1F22/node), for the CNs. Both MNs under test — ds1928d
(`powerlink.cdc`) and openPOWERLINK's demo MN (`-c`) — boot the demo CN from the same file, so the
cycle is changed in both places and nothing else; every other entry (mapping, PRes timeouts,
loss-of-frame tolerance, payload limits) stays as openCONFIGURATOR wrote it.
--prc-node N makes node N a PollResponse Chaining node for openPOWERLINK's MN (EPSG DS 302-C):
bit 14 (PRES_CHAINING, 0x4000) in every NMT_NodeAssignment 0x1F81/N of the MN, and an
assignment 0x1F81/240 = NODE_EXISTS | MN_PRES | VALID (0x80001001) appended, so that the MN sends
its PResMN (its payload limit 0x1F8D/240 and 0x1F98/5 keep the object dictionary's 36 bytes).
--mux-node N makes node N a multiplexed CN the way openCONFIGURATOR writes it (EPSG DS 301):
bit 9 (MULTIPLEXED_CN, 0x200) in NMT_NodeAssignment 0x1F81/N, NMT_MultiplCycleAssign 0x1F9B/N = 1
(the cycle of the multiplexed cycle it is polled in), and NMT_CycleTiming.MultiplCycleCnt 0x1F98/7
= C (--mux-count, default 4) for the MN and inside node N's concise DCF.
--list prints the entries (nested ones indented) instead of writing.
"""
import argparse
import struct
import sys

CYCLE_LEN = 0x1006
CN_DCF = 0x1F22
NODE_ASSIGNMENT = 0x1F81
PRES_CHAINING = 0x4000
MN_PRES_ASSIGNMENT = 0x80001001  # VALID | MN_PRES | NODE_EXISTS
MN_NODE = 240
MULTIPLEXED_CN = 0x200
CYCLE_TIMING = 0x1F98
MULTIPL_CYCLE_ASSIGN = 0x1F9B


def append(out, count, index, sub, value, depth, out_lines):
    out += struct.pack("<HBI", index, sub, len(value)) + value
    out_lines.append("%s%04X/%d = 0x%s" % ("  " * depth, index, sub, bytes(reversed(value)).hex()))
    return count + 1


def rewrite(data, cycle_us, depth, out_lines, prc_nodes=(), mux_nodes=(), mux_count=4,
            mux_here=False):
    if len(data) < 4:
        raise ValueError("concise DCF shorter than its entry count")
    count = struct.unpack_from("<I", data, 0)[0]
    off = 4
    out = bytearray(data[:4])
    for _ in range(count):
        if off + 7 > len(data):
            raise ValueError("concise DCF truncated at byte %d" % off)
        index, sub, size = struct.unpack_from("<HBI", data, off)
        value = data[off + 7:off + 7 + size]
        if len(value) != size:
            raise ValueError("entry %04X/%d truncated" % (index, sub))
        if index == CN_DCF and size >= 4:
            out_lines.append("%s%04X/%d: concise DCF of node %d" % ("  " * depth, index, sub, sub))
            value = rewrite(value, cycle_us, depth + 1, out_lines,
                            mux_count=mux_count, mux_here=sub in mux_nodes)
        elif index == CYCLE_LEN and sub == 0 and size == 4 and cycle_us is not None:
            value = struct.pack("<I", cycle_us)
        elif depth == 0 and index == NODE_ASSIGNMENT and sub in prc_nodes and size == 4:
            value = struct.pack("<I", struct.unpack("<I", value)[0] | PRES_CHAINING)
        elif depth == 0 and index == NODE_ASSIGNMENT and sub in mux_nodes and size == 4:
            value = struct.pack("<I", struct.unpack("<I", value)[0] | MULTIPLEXED_CN)
        if index != CN_DCF or size < 4:
            out_lines.append("%s%04X/%d = 0x%s" % ("  " * depth, index, sub,
                                                   bytes(reversed(value)).hex() or "-"))
        out += struct.pack("<HBI", index, sub, len(value)) + value
        off += 7 + size
    added = 0
    if mux_here or (depth == 0 and mux_nodes):
        added = append(out, added, CYCLE_TIMING, 7, struct.pack("<B", mux_count), depth, out_lines)
    if depth == 0:
        for n in mux_nodes:
            added = append(out, added, MULTIPL_CYCLE_ASSIGN, n, struct.pack("<B", 1), depth,
                           out_lines)
    if added:
        out[0:4] = struct.pack("<I", count + added)
        count += added
    if depth == 0 and prc_nodes:
        value = struct.pack("<I", MN_PRES_ASSIGNMENT)
        out += struct.pack("<HBI", NODE_ASSIGNMENT, MN_NODE, 4) + value
        out[0:4] = struct.pack("<I", count + 1)
        out_lines.append("%04X/%d = 0x%08x" % (NODE_ASSIGNMENT, MN_NODE, MN_PRES_ASSIGNMENT))
    return bytes(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input")
    ap.add_argument("output", nargs="?")
    ap.add_argument("--cycle-us", type=int)
    ap.add_argument("--prc-node", type=int, action="append", default=[])
    ap.add_argument("--mux-node", type=int, action="append", default=[])
    ap.add_argument("--mux-count", type=int, default=4)
    ap.add_argument("--list", action="store_true")
    a = ap.parse_args()
    with open(a.input, "rb") as f:
        data = f.read()
    lines = []
    out = rewrite(data, a.cycle_us, 0, lines, tuple(a.prc_node), tuple(a.mux_node), a.mux_count)
    if a.list:
        print("\n".join(lines))
        return 0
    if not a.output or (a.cycle_us is None and not a.prc_node and not a.mux_node):
        ap.error("OUT.cdc and --cycle-us, --prc-node or --mux-node are needed unless --list")
    with open(a.output, "wb") as f:
        f.write(out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
