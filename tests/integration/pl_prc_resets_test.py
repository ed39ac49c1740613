#!/usr/bin/env python3
"""The PRC hold's reset verdict (pl_prc_resets.py) on made-up captures: each reset must be put down
to the cause the wire shows right before it, and a reset the wire does not explain must be said,
or the hold would pass on the MN's own miscounting."""
import os
import subprocess
import sys
import tempfile
import unittest

HERE = os.path.dirname(os.path.abspath(__file__))
PERIOD = 1e-3
OPERATIONAL = "0xfd"


class Capture:
    """Rows as tshark gives them: time, MessageType, source, destination, SoA service, ASnd
    service, NMTCommandId, PRes state, IdentResponse state, StatusResponse state, SoA target."""

    def __init__(self):
        self.rows = []
        self.t = 100.0

    def row(self, t, mtyp, src, dst, pres_stat="", cid="", asnd=""):
        self.rows.append([f"{t:.9f}", str(mtyp), str(src), str(dst), "", asnd, cid, pres_stat,
                          "", "", ""])

    def cycles(self, n, pres_delay=5e-6, gap=PERIOD):
        """n mixed cycles: SoC, PResMN, node 1's PRC PRes `pres_delay` after it, SoA."""
        for i in range(n):
            self.t += gap if i == 0 else PERIOD
            self.row(self.t, 1, 240, 255)
            self.row(self.t + 10e-6, 4, 240, 255, OPERATIONAL)
            self.row(self.t + 10e-6 + pres_delay, 4, 1, 255, OPERATIONAL)
            self.row(self.t + 400e-6, 5, 240, 255)

    def reset(self, node=1):
        self.row(self.t + 500e-6, 6, 240, node, cid="0x28", asnd="0x04")

    def polled_cycles(self, n, node=3, pres_delay=50e-6):
        """n cycles polling `node` with PReq/PRes, its PRes `pres_delay` after the PReq."""
        for _ in range(n):
            self.t += PERIOD
            self.row(self.t, 1, 240, 255)
            self.row(self.t + 10e-6, 3, 240, node)
            self.row(self.t + 10e-6 + pres_delay, 4, node, 255, OPERATIONAL)
            self.row(self.t + 600e-6, 5, 240, 255)

    def judge(self, stalls=(), options=()):
        """stalls: (cpu, start, end) as host_stall_probe writes them."""
        with tempfile.NamedTemporaryFile("w", suffix=".tsv", delete=False) as f:
            for r in self.rows:
                f.write("\t".join(r) + "\n")
        with tempfile.NamedTemporaryFile("w", suffix=".txt", delete=False) as p:
            for cpu, a, b in stalls:
                p.write("%d %.6f %.6f %.3f\n" % (cpu, a, b, (b - a) * 1e3))
        try:
            out = subprocess.run([sys.executable, os.path.join(HERE, "pl_prc_resets.py"),
                                  *options, f.name, "168", "5", "220", "100", p.name], check=True,
                                 capture_output=True, text=True).stdout
        finally:
            os.unlink(f.name)
            os.unlink(p.name)
        return dict(kv.split("=", 1) for kv in out.split() if "=" in kv)


class PrcResets(unittest.TestCase):
    def test_held_cycles_have_no_reset(self):
        c = Capture()
        c.cycles(500)
        v = c.judge()
        self.assertEqual((v["resets"], v["unexplained"]), ("0", "0"))

    def test_pres_outside_the_slot_after_a_gap_is_the_pres_not_the_gap(self):
        # The MN stalls 9 ms; then node 1's PRes comes 300 µs after the PResMN (outside the
        # 220 µs slot) for 25 cycles: the counter reaches 168 and the MN resets the node.
        c = Capture()
        c.cycles(100)
        c.cycles(1, gap=9e-3)
        c.cycles(25, pres_delay=300e-6)
        c.reset()
        v = c.judge()
        self.assertEqual((v["resets"], v["pres_missing"], v["soc_gap"], v["unexplained"]),
                         ("1", "1", "0", "0"))

    def test_a_gap_right_before_a_reset_explains_it_the_host_when_a_cpu_stood_still(self):
        c = Capture()
        c.cycles(100)
        gap_from = c.t
        c.cycles(3, gap=12e-3)
        c.reset()
        # CPU 1's probe stopped from 0.5 ms into the gap to 0.3 ms before its end: the host's.
        v = c.judge([(0, gap_from - 0.2, gap_from - 0.19),
                     (1, gap_from + 0.5e-3, gap_from + 11.7e-3)])
        self.assertEqual(
            (v["resets"], v["soc_gap"], v["unexplained"], v["host_stalled"], v["gaps_host"]),
            ("1", "1", "0", "1", "1"))
        # A stop of 5 ms inside a 12 ms gap does not account for it.
        v = c.judge([(1, gap_from + 2e-3, gap_from + 7e-3)])
        self.assertEqual((v["resets"], v["host_stalled"], v["gaps_host"]), ("1", "0", "0"))

    def test_a_gap_long_before_a_reset_does_not(self):
        # 12 ms gap, then 3 s of good cycles, then a reset: nothing on the wire explains it.
        c = Capture()
        c.cycles(100)
        c.cycles(3000, gap=12e-3)
        c.reset()
        v = c.judge()
        self.assertEqual((v["resets"], v["unexplained"]), ("1", "1"))

    def test_a_preq_node_answering_after_its_pres_timeout_is_lost(self):
        # Node 3's PRes comes 190 µs after its PReq for 25 cycles: inside the cycle and the
        # 220 µs PRC slot, but past the MN's 200 µs PResTimeout less the stamps' 20 µs tolerance.
        # The MN counts each lost (+8): 21 of them reach 168 and it resets the node.
        c = Capture()
        c.polled_cycles(100)
        c.polled_cycles(25, pres_delay=190e-6)
        c.reset(node=3)
        v = c.judge(options=("--pres-timeout-us", "200"))
        self.assertEqual((v["resets"], v["pres_missing"], v["unexplained"]), ("1", "1", "0"))
        # (the last cycle has no SoC after it: not closed, not counted)
        self.assertEqual(v["cycles_without_pres"], "3:24")
        # Without the MN's timeout the replay takes SLOT_US: those PRes were in time, and the
        # reset is the MN's miscount.
        v = c.judge()
        self.assertEqual((v["resets"], v["unexplained"]), ("1", "1"))
        # PRes 150 µs after the PReq were in time: a reset after them is not explained.
        c = Capture()
        c.polled_cycles(125, pres_delay=150e-6)
        c.reset(node=3)
        v = c.judge(options=("--pres-timeout-us", "200"))
        self.assertEqual((v["resets"], v["unexplained"]), ("1", "1"))

    def test_a_reset_out_of_the_blue_is_unexplained(self):
        c = Capture()
        c.cycles(300)
        c.reset()
        c.cycles(300)
        v = c.judge()
        self.assertEqual((v["resets"], v["unexplained"]), ("1", "1"))


if __name__ == "__main__":
    unittest.main()
