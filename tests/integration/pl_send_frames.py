#!/usr/bin/env python3
"""Sends hand-made POWERLINK frames on a raw socket, unpadded, as a software MN/CN on a
veth/TAP link does. Used by the namespace tests (root).

  pl_send_frames.py IFACE KIND:COUNT:LENGTH ...   [--after-soa-from 240] [--timeout S]

KIND: soc | soa-ident (SoA IdentRequest to node 1) | soa-none | pres (PRes of node 1, 6-byte
payload). LENGTH: bytes on the wire without FCS (54 = 14 Ethernet + 40 POWERLINK; shorter
lengths cut the message's fields, to check that truncated frames are refused).
--after-soa-from N: first wait until a SoA from node N is seen (the receiver's socket is open).
--every MS: one frame every MS milliseconds instead of all at once (COUNT 0: until killed).
--bypass: send past the qdisc (PACKET_QDISC_BYPASS), as ds1928d's own socket does: the frames
  then go to the link's other end only, not to another packet socket on the sending interface
  (a CN there would take a SoC of ours for its MN's).
Then, so that the caller knows every frame above was handled (a socket's frames are handled in
order), one of:
--probe-ident: send a 54-byte SoA IdentRequest to node 1 every 100 ms until node 1's
  IdentResponse comes (a CN answering); prints "probes N".
--answer-ident: wait for the MN's SoA IdentRequest to node 1 and answer it with node 1's
  IdentResponse (176 bytes): the MN's boot state of node 1 changes.
"""
import socket
import struct
import sys
import time

ETH_P_PLK = 0x88AB
MAC_SRC = bytes([0x02, 0x00, 0x00, 0x00, 0x54, 0x54])


def header(dst_mac, msg_type, dst, src):
    return dst_mac + MAC_SRC + struct.pack(">H", ETH_P_PLK) + bytes([msg_type, dst, src])


def frame(kind, length):
    if kind == "soc":
        f = header(bytes.fromhex("01111e000001"), 0x01, 255, 240) + bytes([0, 0, 0])
        f += struct.pack("<IIQ", int(time.time()), 0, 1000)
    elif kind in ("soa-ident", "soa-none"):
        service, target = (1, 1) if kind == "soa-ident" else (0, 0)
        f = header(bytes.fromhex("01111e000003"), 0x05, 255, 240)
        f += bytes([0x1D, 0, 0, service, target, 0x20])
    elif kind == "pres":
        f = header(bytes.fromhex("01111e000002"), 0x04, 255, 1)
        f += bytes([0xFD, 0x01, 0, 0x20, 0]) + struct.pack("<H", 6) + bytes(range(1, 7))
    else:
        raise SystemExit("unknown kind " + kind)
    f = f.ljust(length, b"\0")
    return f[:length]


def ident_response():
    f = header(bytes.fromhex("01111e000004"), 0x06, 240, 1)
    f += bytes([0x01, 0, 0, 0x1D, 0, 0x20, 0])  # IdentResponse, PRE_OPERATIONAL_1, EPLVersion
    return f.ljust(176, b"\0")


def recv_until(s, deadline, match):
    while True:
        s.settimeout(max(0.001, deadline - time.monotonic()))
        try:
            data = s.recv(2048)
        except socket.timeout:
            return False
        if len(data) > 21 and match(data):
            return True


def is_ident_request(d):
    return d[14] & 0x7F == 0x05 and d[16] == 240 and d[20] == 1 and d[21] == 1


def is_ident_response(d):
    return d[14] & 0x7F == 0x06 and d[16] == 1 and d[17] == 1


def main():
    args = sys.argv[1:]
    iface = args.pop(0)
    after_soa_from = None
    timeout = 30.0
    specs = []
    probe = answer = bypass = False
    every = 0.0
    while args:
        a = args.pop(0)
        if a == "--probe-ident":
            probe = True
        elif a == "--answer-ident":
            answer = True
        elif a == "--after-soa-from":
            after_soa_from = int(args.pop(0))
        elif a == "--every":
            every = float(args.pop(0)) / 1000.0
        elif a == "--bypass":
            bypass = True
        elif a == "--timeout":
            timeout = float(args.pop(0))
        else:
            kind, count, length = a.split(":")
            specs.append((kind, int(count), int(length)))
    s = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(ETH_P_PLK))
    s.bind((iface, 0))
    if bypass:
        s.setsockopt(263, 20, 1)  # SOL_PACKET, PACKET_QDISC_BYPASS (linux/if_packet.h)
    if after_soa_from is not None:
        s.settimeout(timeout)
        while True:
            data = s.recv(2048)
            if len(data) > 16 and data[14] & 0x7F == 0x05 and data[16] == after_soa_from:
                break
    sent = 0
    for kind, count, length in specs:
        f = frame(kind, length)
        n = 0
        while count == 0 or n < count:
            s.send(f)
            sent += 1
            n += 1
            if every > 0:
                time.sleep(every)
    print("sent %d frames" % sent)
    deadline = time.monotonic() + timeout
    if probe:
        probes = 0
        while True:
            if time.monotonic() > deadline:
                raise SystemExit("no IdentResponse from node 1")
            s.send(frame("soa-ident", 54))
            probes += 1
            if recv_until(s, min(deadline, time.monotonic() + 0.1), is_ident_response):
                break
        print("probes %d" % probes)
    if answer:
        if not recv_until(s, deadline, is_ident_request):
            raise SystemExit("no IdentRequest to node 1")
        s.send(ident_response())
        print("answered IdentRequest")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
