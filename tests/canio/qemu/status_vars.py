#!/usr/bin/env python3
"""Prints the CAN-I/O part of `ds1928ctl --json status` as shell assignments (for eval).

Usage: status_vars.py STATUS_JSON_FILE [AXIS]
       status_vars.py --serve   (a coprocess: reads "FILE AXIS" lines, answers each with the
                                 assignments and a line "#end"; one interpreter start, which in
                                 the TCG guest costs seconds, for the whole test)
Prints bus_kind, bus_state, transport, interface, can_state, bitrate, restart_ms, the bus counters
(c_<name>), and for the axis' node: configured (1/0), silent, in_id0, in_id1, out_id (decimal) and
its counters (n_<name>), last_error, and its CANopen node's fields (cn_<name>: nmt_state,
nmt_starts, boot_ups, heartbeats, ...). Unknown or missing fields print empty values, so a check on
them fails with the status in the log rather than here.
"""
import json
import shlex
import sys


def assignments(path: str, axis: int) -> list:
    try:
        with open(path) as f:
            lines = [l for l in f.read().splitlines() if l.strip()]
        doc = json.loads(lines[-1]) if lines else {}
    except (OSError, json.JSONDecodeError) as e:
        return [f"status_error={shlex.quote(str(e))}"]
    if "bus" not in doc and isinstance(doc.get("result"), dict):
        doc = doc["result"]
    bus = doc.get("bus", {}) if isinstance(doc.get("bus"), dict) else {}
    out = {
        "bus_kind": bus.get("kind", ""),
        "bus_state": bus.get("state", ""),
        "transport": bus.get("transport", ""),
        "interface": bus.get("interface", ""),
        "can_state": bus.get("can_state", ""),
        "bitrate": bus.get("bitrate", ""),
        "restart_ms": bus.get("restart_ms", ""),
    }
    for k, v in (bus.get("counters") or {}).items():
        out[f"c_{k}"] = v
    nodes = bus.get("nodes") or []
    node = next((n for n in nodes if n.get("axis") == axis), None)
    if node is not None:
        ids = node.get("input_ids") or ["", ""]
        out.update({
            "node": node.get("node", ""),
            "configured": 1 if node.get("configured") else 0,
            "n_state": node.get("state", ""),
            "silent": 1 if node.get("silent") else 0,
            "in_id0": ids[0],
            "in_id1": ids[1] if len(ids) > 1 else "",
            "out_id": node.get("output_id", ""),
            "last_error": node.get("last_error", ""),
        })
        for k, v in node.items():
            if isinstance(v, int) and not isinstance(v, bool) and k not in ("axis", "node", "output_id"):
                out[f"n_{k}"] = v
    # The CANopen node of that axis (NMT, boot-up, heartbeat, EMCY): cn_<name>.
    cns = bus.get("canopen_nodes") or []
    cn = next((c for c in cns if node is not None and c.get("node") == node.get("node")), None)
    if cn is not None:
        for k, v in cn.items():
            if isinstance(v, bool):
                out[f"cn_{k}"] = 1 if v else 0
            elif isinstance(v, (int, str)) and k != "node":
                out[f"cn_{k}"] = v
    return [f"{k}={shlex.quote(str(v))}" for k, v in out.items()]


def main() -> int:
    if sys.argv[1:] == ["--serve"]:
        for line in sys.stdin:
            path, _, axis = line.strip().partition(" ")
            print("\n".join(assignments(path, int(axis or 0))))
            print("#end", flush=True)
        return 0
    print("\n".join(assignments(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 0)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
