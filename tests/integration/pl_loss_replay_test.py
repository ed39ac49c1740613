#!/usr/bin/env python3
"""The wire replay of the loss-of-PRes counter (pl_loss_replay.py) on made-up cycles: it must fire
exactly where the EPSG DS 301 counter does, or the opl_cn test would explain resets it should not."""
import os
import sys
import unittest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from pl_loss_replay import replay  # noqa: E402

PERIOD = 1e-3
TIMEOUT = 200e-6
TOL = 20e-6


def cycles(delays):
    """One cycle per entry: the PReq 5 µs after the SoC, its PRes `delay` s later (None: none)."""
    socs, preqs, pres = [], [], []
    for i, d in enumerate(delays):
        soc = 100.0 + i * PERIOD
        socs.append(soc)
        preqs.append(soc + 5e-6)
        if d is not None:
            pres.append(soc + 5e-6 + d)
    return socs, preqs, pres


class Replay(unittest.TestCase):
    def run_replay(self, delays, threshold=168):
        return replay(1, TIMEOUT, threshold, *cycles(delays), TOL)

    def test_in_time_never_fires(self):
        fired, stats = self.run_replay([50e-6] * 1000)
        self.assertEqual(fired, {"upper": 0, "lower": 0})
        self.assertEqual((stats["late"], stats["missing"], stats["peak"]), (0, 0, 0))

    def test_21_silent_cycles_fire_once_20_do_not(self):
        # 168 / 8 = 21 errors in a row reach the threshold; 20 (160) do not.
        fired, _ = self.run_replay([50e-6] * 10 + [None] * 21 + [50e-6] * 10)
        self.assertEqual(fired, {"upper": 1, "lower": 1})
        fired, stats = self.run_replay([50e-6] * 10 + [None] * 20 + [50e-6] * 10)
        self.assertEqual(fired, {"upper": 0, "lower": 0})
        self.assertEqual(stats["peak"], 160)

    def test_late_answers_count_as_lost(self):
        fired, stats = self.run_replay([500e-6] * 21)
        self.assertEqual(fired["upper"], 1)
        self.assertEqual(stats["late"], 21)

    def test_sparse_losses_do_not_add_up(self):
        # One loss every 9 cycles: +8 −8 per 9 cycles, the counter never climbs.
        fired, stats = self.run_replay(([None] + [50e-6] * 8) * 200)
        self.assertEqual(fired["upper"], 0)
        self.assertEqual(stats["peak"], 8)

    def test_answers_near_the_timeout_count_only_in_the_upper_bound(self):
        fired, stats = self.run_replay([TIMEOUT + 5e-6] * 21)
        self.assertEqual(fired, {"upper": 1, "lower": 0})
        self.assertEqual(stats["near"], 21)

    def test_an_answer_after_the_next_preq_is_missing_there_and_late_in_the_next(self):
        # The PRes carries no cycle number: a PRes 1.5 ms late is no answer in its own cycle and
        # a late one (500 µs) in the next, where the MN takes it for the answer to that PReq.
        fired, stats = self.run_replay([1.5e-3, None, 50e-6])
        self.assertEqual((stats["missing"], stats["late"]), (1, 1))
        self.assertEqual(fired["upper"], 0)

    def test_cycles_without_a_preq_to_the_node_count_down(self):
        socs, preqs, pres = cycles([None] * 20)
        socs += [socs[-1] + PERIOD * (i + 1) for i in range(8)]  # 8 cycles, node not polled
        socs += [socs[-1] + PERIOD]
        preqs.append(socs[-1] + 5e-6)  # one more error: 160 − 8 + 8 = 160 < 168
        fired, stats = replay(1, TIMEOUT, 168, socs, preqs, pres, TOL)
        self.assertEqual(fired["upper"], 0)
        self.assertEqual(stats["peak"], 160)

    def test_the_counter_restarts_after_firing(self):
        fired, _ = self.run_replay([None] * 42)
        self.assertEqual(fired["upper"], 2)


if __name__ == "__main__":
    unittest.main()
