#!/usr/bin/env python3
"""Prints, per interface of a pcapng file, "IF NAME EPBS OUT IN IFRECV IFDROP": the interface's
name, its enhanced packet blocks (all, outbound, inbound by epb_flags) and its interface
statistics (isb_ifrecv, isb_ifdrop; - when absent). An independent reader of what ds1928d wrote,
for the capture tests."""
import struct
import sys

data = open(sys.argv[1], "rb").read()
pos = 0
names, epbs, out, inb, recv, drop = [], [], [], [], [], []


def options(body):
    o, res = 0, {}
    while o + 4 <= len(body):
        code, length = struct.unpack_from("<HH", body, o)
        if code == 0:
            break
        res[code] = body[o + 4:o + 4 + length]
        o += 4 + (length + 3) // 4 * 4
    return res


while pos + 12 <= len(data):
    btype, blen = struct.unpack_from("<II", data, pos)
    if blen < 12 or pos + blen > len(data):
        sys.exit("truncated block at %d" % pos)
    if struct.unpack_from("<I", data, pos + blen - 4)[0] != blen:
        sys.exit("block lengths differ at %d" % pos)
    body = data[pos + 8:pos + blen - 4]
    if btype == 1:
        opts = options(body[8:])
        names.append(opts.get(2, b"?").decode())
        for lst, v in ((epbs, 0), (out, 0), (inb, 0), (recv, "-"), (drop, "-")):
            lst.append(v)
    elif btype == 6:
        iface, _, _, caplen = struct.unpack_from("<IIII", body, 0)
        opts = options(body[20 + (caplen + 3) // 4 * 4:])
        epbs[iface] += 1
        flags = struct.unpack("<I", opts[2])[0] if 2 in opts else 0
        if flags & 3 == 2:
            out[iface] += 1
        elif flags & 3 == 1:
            inb[iface] += 1
    elif btype == 5:
        iface = struct.unpack_from("<I", body, 0)[0]
        opts = options(body[12:])
        recv[iface] = struct.unpack("<Q", opts[4])[0] if 4 in opts else "-"
        drop[iface] = struct.unpack("<Q", opts[5])[0] if 5 in opts else "-"
    pos += blen
if pos != len(data):
    sys.exit("trailing bytes at %d" % pos)
for i, n in enumerate(names):
    print(i, n.replace(" ", "_"), epbs[i], out[i], inb[i], recv[i], drop[i])
