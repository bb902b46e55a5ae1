#!/usr/bin/env python3
"""Which executed-jerk samples over the limit follow a gap in the control loop's samples.

Usage: scripts/analysis/jerk_after_gaps.py RUN_DIR [RUN_DIR ...] [--limit R] [--gap S]

Reads RUN_DIR/robot.csv (the states the control loop read; simulated data when the run was on
the simulator or the emulator), computes the executed jerk of every joint as the second
derivative of actual_qd over the real sample spacing (the three-point formula for uneven
spacing), and counts the samples whose largest joint jerk exceeds --limit [rad/s^3] (default
32.8 = 1.1 x the largest planner limit of the demo, 29.85). For each it looks back 60 ms of
controller time for a gap between consecutive samples of at least --gap [s] (default 0.020).
This is an analysis aid for BENCHMARKS.md; summary.json's own counts (judged against each
cycle's limit) are what tests and reports use.
"""
import argparse
import csv
import os


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--limit", type=float, default=32.8)
    ap.add_argument("--gap", type=float, default=0.020)
    a = ap.parse_args()
    for d in a.runs:
        path = os.path.join(d, "robot.csv")
        if not os.path.exists(path):
            raise SystemExit(f"{path}: no robot.csv (pass a run folder)")
        with open(path, newline="") as f:
            rows = list(csv.DictReader(f))
        t = [float(r["timestamp"]) for r in rows]
        qd = [[float(r[f"actual_qd_{j}"]) for j in range(6)] for r in rows]
        over = []
        for i in range(1, len(t) - 1):
            h1, h2 = t[i] - t[i - 1], t[i + 1] - t[i]
            if h1 <= 0 or h2 <= 0:
                continue
            jm = max(
                abs(2 * ((qd[i + 1][j] - qd[i][j]) / h2 - (qd[i][j] - qd[i - 1][j]) / h1) / (h1 + h2))
                for j in range(6)
            )
            if jm > a.limit:
                over.append(i)
        after_gap = 0
        for i in over:
            k, g = i, 0.0
            while k > 0 and t[i] - t[k] < 0.06:
                g = max(g, t[k] - t[k - 1])
                k -= 1
            after_gap += g >= a.gap - 1e-4
        gaps = sum(1 for i in range(1, len(t)) if t[i] - t[i - 1] >= a.gap - 1e-4)
        print(f"{d}: {len(t)} samples, {len(over)} over {a.limit} rad/s^3, "
              f"{after_gap} of them within 60 ms after a gap >= {a.gap * 1000:.0f} ms; "
              f"{gaps} such gaps")


if __name__ == "__main__":
    main()
