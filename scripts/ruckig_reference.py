#!/usr/bin/env python3
"""Reference durations from the C++ Ruckig (PyPI `ruckig` 0.19.4) for the rsruckig cross-check.

Generates seeded random 6-DoF state-to-state problems (current position/velocity/acceleration,
target position/velocity/acceleration, per-DoF velocity/acceleration/jerk limits; some with a
minimum duration) and writes each with Ruckig's trajectory duration to
`adapt/tests/fixtures/ruckig_reference.csv`. The Rust test `adapt/tests/otg_vs_ruckig.rs` reads
that fixture; CI runs only the test, never this script.

Set-up (not committed):
    python3 -m venv /tmp/ruckig-venv && /tmp/ruckig-venv/bin/pip install ruckig==0.19.4
    /tmp/ruckig-venv/bin/python scripts/ruckig_reference.py [--count 1200] [--seed 4]

Problem classes (chosen round-robin so every class is represented):
  rest      current and target at rest (the handover's point-to-point motions)
  moving    random current velocity/acceleration, target at rest (online retargeting)
  general   random current and target velocity/acceleration
  brake     current velocity above the limit (Ruckig's braking pre-trajectory)
  mindur    as `moving`, with a minimum duration between 0.5x and 3x the time-optimal one
Problems the reference rejects (invalid target state) are redrawn; the file records the
class of each problem. Floats are written with repr(), which round-trips exactly.
"""

import argparse
import csv
import math
import os
import random
import sys

import ruckig
from ruckig import InputParameter, Result, Ruckig, Trajectory

DOF = 6
CLASSES = ["rest", "moving", "general", "brake", "mindur"]
FIELDS = ["cp", "cv", "ca", "tp", "tv", "ta", "vmax", "amax", "jmax"]


def draw(rng: random.Random, kind: str):
    vmax = [rng.uniform(0.2, 4.0) for _ in range(DOF)]
    amax = [rng.uniform(0.2, 10.0) for _ in range(DOF)]
    jmax = [rng.uniform(0.5, 100.0) for _ in range(DOF)]
    cp = [rng.uniform(-2 * math.pi, 2 * math.pi) for _ in range(DOF)]
    tp = [rng.uniform(-2 * math.pi, 2 * math.pi) for _ in range(DOF)]
    zero = [0.0] * DOF
    cv, ca, tv, ta = zero[:], zero[:], zero[:], zero[:]
    if kind in ("moving", "general", "mindur"):
        cv = [rng.uniform(-1, 1) * vmax[i] for i in range(DOF)]
        ca = [rng.uniform(-1, 1) * amax[i] for i in range(DOF)]
    if kind == "general":
        tv = [rng.uniform(-1, 1) * vmax[i] for i in range(DOF)]
        ta = [rng.uniform(-1, 1) * amax[i] for i in range(DOF)]
    if kind == "brake":
        cv = [rng.choice([-1, 1]) * rng.uniform(1.0, 1.5) * vmax[i] for i in range(DOF)]
        ca = [rng.uniform(-0.5, 0.5) * amax[i] for i in range(DOF)]
    # Occasionally a DoF that does not need to move at all.
    if rng.random() < 0.1:
        i = rng.randrange(DOF)
        tp[i], cv[i], ca[i], tv[i], ta[i] = cp[i], 0.0, 0.0, 0.0, 0.0
    return dict(cp=cp, cv=cv, ca=ca, tp=tp, tv=tv, ta=ta, vmax=vmax, amax=amax, jmax=jmax)


def solve(p, minimum_duration=None):
    inp = InputParameter(DOF)
    for name, attr in [
        ("cp", "current_position"), ("cv", "current_velocity"), ("ca", "current_acceleration"),
        ("tp", "target_position"), ("tv", "target_velocity"), ("ta", "target_acceleration"),
        ("vmax", "max_velocity"), ("amax", "max_acceleration"), ("jmax", "max_jerk"),
    ]:
        setattr(inp, attr, p[name])
    if minimum_duration is not None:
        inp.minimum_duration = minimum_duration
    otg = Ruckig(DOF, 0.002)
    traj = Trajectory(DOF)
    try:
        res = otg.calculate(inp, traj)
    except (RuntimeError, ruckig.RuckigError):
        return None
    if res not in (Result.Working, Result.Finished):
        return None
    return traj.duration


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=1200)
    ap.add_argument("--seed", type=int, default=4)
    here = os.path.dirname(os.path.abspath(__file__))
    ap.add_argument(
        "--out",
        default=os.path.join(here, "..", "adapt", "tests", "fixtures", "ruckig_reference.csv"),
    )
    args = ap.parse_args()
    version = getattr(ruckig, "__version__", "unknown")
    if version != "0.19.4":
        print(f"warning: ruckig {version}, the fixture is meant for 0.19.4", file=sys.stderr)

    rng = random.Random(args.seed)
    rows, redrawn = [], 0
    while len(rows) < args.count:
        kind = CLASSES[len(rows) % len(CLASSES)]
        p = draw(rng, kind)
        mindur = None
        optimal = solve(p)
        if optimal is None:
            redrawn += 1
            continue
        if kind == "mindur":
            mindur = optimal * rng.uniform(0.5, 3.0)
            duration = solve(p, mindur)
            if duration is None:
                redrawn += 1
                continue
        else:
            duration = optimal
        row = {"id": len(rows), "class": kind}
        for f in FIELDS:
            for i, x in enumerate(p[f]):
                row[f"{f}_{i}"] = repr(float(x))
        row["minimum_duration"] = "" if mindur is None else repr(float(mindur))
        row["duration"] = repr(float(duration))
        rows.append(row)

    os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
    header = ["id", "class"] + [f"{f}_{i}" for f in FIELDS for i in range(DOF)]
    header += ["minimum_duration", "duration"]
    with open(args.out, "w", newline="") as fh:
        fh.write(f"# ruckig {version} (C++ via PyPI), seed {args.seed}, delta_time 0.002 s, "
                 f"{len(rows)} problems, {redrawn} redrawn; scripts/ruckig_reference.py\n")
        w = csv.DictWriter(fh, fieldnames=header, lineterminator="\n")
        w.writeheader()
        w.writerows(rows)
    print(f"wrote {len(rows)} problems ({redrawn} redrawn) to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
