#!/usr/bin/env python3
"""Frame conventions of the bundled KTH handover recording, worked out from the data itself.

Usage: python3 scripts/analysis/kth_frames.py [data/human-motion/kth-handover]

Standard library only. It prints the evidence quoted in the module docs of
`assess/src/io/kth.rs`:
  1. file sanity (rows, columns, non-finite values, quaternion norms);
  2. which world axis is up (heights of head, chest, hip, hands);
  3. which quaternion component is the scalar w, and whether q maps body -> world, from rigidity:
     a child segment's origin (its proximal joint), expressed in the parent segment's frame, must stay
     (nearly) constant. Only the right convention makes it so;
  4. the body axes of head and chest: which points up, which points toward the giver/baton;
  5. the transfer: baton-hand distances, baton and hand speeds, wrench magnitudes.
"""

import csv
import math
import os
import sys

HZ = 120.0


def load(path):
    rows = []
    with open(path, newline="") as f:
        r = csv.reader(f)
        header = next(r)
        for k, row in enumerate(r, start=2):
            if len(row) != len(header):
                print(f"  {os.path.basename(path)}:{k}: {len(row)} fields, expected {len(header)}")
            vals = [float(v) if v.strip() else float("nan") for v in row]
            rows.append(vals)
    return header, rows


def quat_to_matrix(w, x, y, z):
    """Rotation matrix of the unit quaternion w + xi + yj + zk (Hamilton), rows as lists."""
    n = math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


ORDERS = {
    "w=q0 (q0,q1,q2,q3 = w,x,y,z)": lambda q: (q[0], q[1], q[2], q[3]),
    "w=q3 (q0,q1,q2,q3 = x,y,z,w)": lambda q: (q[3], q[0], q[1], q[2]),
}


def rot(row, order, body_to_world=True):
    m = quat_to_matrix(*ORDERS[order](row[3:7]))
    if not body_to_world:
        m = [[m[j][i] for j in range(3)] for i in range(3)]
    return m


def mat_t_vec(m, v):  # m^T v
    return [sum(m[j][i] * v[j] for j in range(3)) for i in range(3)]


def col(m, i):
    return [m[0][i], m[1][i], m[2][i]]


def sub(a, b):
    return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]


def norm(a):
    return math.sqrt(sum(v * v for v in a))


def angle_deg(a, b):
    c = sum(x * y for x, y in zip(a, b)) / (norm(a) * norm(b))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def median(xs):
    s = sorted(xs)
    n = len(s)
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def std(xs):
    m = sum(xs) / len(xs)
    return math.sqrt(sum((x - m) ** 2 for x in xs) / len(xs))


def speed(pos, k):
    """Central-difference speed [m/s] at row k."""
    a, b = max(0, k - 1), min(len(pos) - 1, k + 1)
    return norm(sub(pos[b], pos[a])) * HZ / (b - a)


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "data/human-motion/kth-handover"
    bodies = {}
    print("== 1. files")
    for name in sorted(os.listdir(d)):
        if not name.endswith(".csv"):
            continue
        header, rows = load(os.path.join(d, name))
        nonfinite = sum(1 for r in rows for v in r if not math.isfinite(v))
        extra = ""
        if name.endswith("_pose_saved.csv"):
            norms = [norm(r[3:7]) for r in rows]
            extra = f" |q| in [{min(norms):.6f}, {max(norms):.6f}]"
            bodies[name[: -len("_pose_saved.csv")]] = rows
        else:
            bodies[name[: -len("_saved.csv")]] = rows
        print(f"  {name}: {len(rows)} rows x {len(header)} cols, non-finite {nonfinite}{extra}")

    pos = {k: [r[0:3] for r in v] for k, v in bodies.items() if not k.startswith("Wrench")}
    n = len(pos["baton"])

    print("\n== 2. up axis: median x, y, z of some bodies [m]")
    for b in ["taker_head", "taker_chest", "taker_hip", "taker_LHand", "taker_RHand", "giver_head", "giver_chest", "baton"]:
        p = pos[b]
        print(f"  {b:14s} x {median([q[0] for q in p]):+.3f}  y {median([q[1] for q in p]):+.3f}  z {median([q[2] for q in p]):+.3f}")

    print("\n== 3. quaternion order and direction from segment rigidity")
    print("  std over all rows of the child's origin in the parent's frame, R_parent^T (p_child - p_parent) [mm],")
    print("  summed over the three axes, then summed over parent->child pairs of both people")
    pairs = [("hip", "ab"), ("ab", "chest"), ("chest", "neck"), ("neck", "head")]
    for s in "LR":
        pairs += [("chest", f"{s}Shoulder"), (f"{s}Shoulder", f"{s}UArm"), (f"{s}UArm", f"{s}FArm"), (f"{s}FArm", f"{s}Hand")]
    results = {}
    for order in ORDERS:
        for b2w in (True, False):
            total = 0.0
            per = []
            for who in ("giver", "taker"):
                for parent, child in pairs:
                    P, C = bodies[f"{who}_{parent}"], bodies[f"{who}_{child}"]
                    locs = []
                    for k in range(n):
                        m = rot(P[k], order, b2w)
                        locs.append(mat_t_vec(m, sub(C[k][0:3], P[k][0:3])))
                    sd = sum(std([l[i] for l in locs]) for i in range(3)) * 1000
                    per.append((f"{who}_{parent}->{child}", sd, [median([l[i] for l in locs]) for i in range(3)]))
                    total += sd
            label = f"{order}, {'body->world' if b2w else 'world->body'}"
            results[label] = (total, per)
            print(f"  {label:50s} total {total:8.1f} mm")
    best = min(results, key=lambda k: results[k][0])
    print(f"  best: {best}")
    for name, sd, med in results[best][1]:
        print(f"    {name:28s} std {sd:6.1f} mm, offset in parent frame [{med[0]:+.3f} {med[1]:+.3f} {med[2]:+.3f}] m")

    print("\n== 5. transfer (before axes, to know the time window)")
    def dist(a, b):
        return [norm(sub(pos[a][k], pos[b][k])) for k in range(n)]
    dd = {h: dist("baton", h) for h in ["taker_LHand", "taker_RHand", "giver_LHand", "giver_RHand"]}
    bv = [speed(pos["baton"], k) for k in range(n)]
    hv = {h: [speed(pos[h], k) for k in range(n)] for h in dd}
    wr = {w: [norm(r[0:3]) for r in bodies[w]] for w in ["Wrench_giver", "Wrench_taker", "Wrench_interaction"]}
    print("  t[s]  row | baton-hand dist [m]: tL    tR    gL    gR | speed [m/s]: baton  gR    tL    tR | |F| [N]: giver taker inter | baton z")
    for k in list(range(0, n, 30)) + [n - 1]:
        print(f"  {k / HZ:5.2f} {k:4d} | {dd['taker_LHand'][k]:.3f} {dd['taker_RHand'][k]:.3f} {dd['giver_LHand'][k]:.3f} {dd['giver_RHand'][k]:.3f}"
              f" | {bv[k]:.3f} {hv['giver_RHand'][k]:.3f} {hv['taker_LHand'][k]:.3f} {hv['taker_RHand'][k]:.3f}"
              f" | {wr['Wrench_giver'][k]:6.2f} {wr['Wrench_taker'][k]:6.2f} {wr['Wrench_interaction'][k]:6.2f} | {pos['baton'][k][2]:.3f}")
    for h in dd:
        print(f"  {h}: min baton distance {min(dd[h]):.3f} m at row {dd[h].index(min(dd[h]))}, last row {dd[h][-1]:.3f} m")
    for w in wr:
        x = wr[w]
        print(f"  {w}: |F| median {median(x):.2f} N, max {max(x):.2f} N at row {x.index(max(x))}")
    print(f"  baton speed: median {median(bv):.3f} m/s, max {max(bv):.3f} m/s at row {bv.index(max(bv))}")
    for h in hv:
        print(f"  {h} speed: median {median(hv[h]):.3f} m/s, max {max(hv[h]):.3f} m/s at row {hv[h].index(max(hv[h]))}")

    print("\n== 4. body axes of head and chest (with the best convention)")
    order = best.split(",")[0]
    b2w = "body->world" in best
    axes = {"+x": (0, 1), "-x": (0, -1), "+y": (1, 1), "-y": (1, -1), "+z": (2, 1), "-z": (2, -1)}
    for o in ORDERS:
        print(f"  -- {o}, {'body->world' if b2w else 'world->body'}" + ("  [best]" if o == order else ""))
        for b, target in [("taker_head", "baton"), ("taker_chest", "baton"), ("taker_head", "giver_head"),
                          ("taker_chest", "giver_chest"), ("giver_head", "baton"), ("giver_chest", "taker_chest")]:
            line = []
            for ax, (i, s) in axes.items():
                up, to = [], []
                for k in range(n):
                    m = rot(bodies[b][k], o, b2w)
                    a = [s * v for v in col(m, i)]
                    up.append(angle_deg(a, [0, 0, 1]))
                    tvec = sub(pos[target][k], pos[b][k])
                    if b.endswith("chest"):
                        # the torso normal is compared with the horizontal direction to the target
                        tvec[2] = 0.0
                        a = [a[0], a[1], 0.0] if norm([a[0], a[1], 0.0]) > 1e-9 else a
                    to.append(angle_deg(a, tvec))
                line.append(f"{ax}: up {median(up):5.1f} to {median(to):5.1f}")
            print(f"    {b:12s} vs {target:12s} median angle [deg]  " + " | ".join(line))


if __name__ == "__main__":
    main()


class OneEuro:
    """Scalar One-Euro filter, as in assess/src/filter.rs (min cutoff 1 Hz, beta 0.05, d cutoff 1 Hz)."""

    def __init__(self, min_cutoff=1.0, beta=0.05, d_cutoff=1.0):
        self.p = (min_cutoff, beta, d_cutoff)
        self.x = None
        self.dx = 0.0

    @staticmethod
    def alpha(fc, dt):
        return 1.0 / (1.0 + 1.0 / (2 * math.pi * fc) / dt)

    def __call__(self, x, dt):
        if self.x is None:
            self.x = x
            return x
        dx = (x - self.x) / dt
        a_d = self.alpha(self.p[2], dt)
        self.dx = a_d * dx + (1 - a_d) * self.dx
        a = self.alpha(self.p[0] + self.p[1] * abs(self.dx), dt)
        self.x = a * x + (1 - a) * self.x
        return self.x


def timeline():
    d = sys.argv[1] if len(sys.argv) > 1 else "data/human-motion/kth-handover"
    names = ["baton", "taker_RHand", "taker_LHand", "giver_RHand", "taker_head", "taker_chest"]
    B = {b: load(os.path.join(d, f"{b}_pose_saved.csv"))[1] for b in names}
    W = {w: load(os.path.join(d, f"Wrench_{w}_saved.csv"))[1] for w in ["giver", "taker"]}
    n = len(B["baton"])
    P = {b: [r[0:3] for r in B[b]] for b in names}
    # filtered taker-hand speeds, as the assessor computes them (dt = 1/120 s)
    fspeed = {}
    for h in ["taker_RHand", "taker_LHand"]:
        f = [OneEuro(), OneEuro(), OneEuro()]
        prev = None
        out = []
        for k in range(n):
            cur = [f[i](P[h][k][i], 1 / HZ) for i in range(3)]
            out.append(norm(sub(cur, prev)) * HZ if prev else float("nan"))
            prev = cur
        fspeed[h] = out
    order = "w=q3 (q0,q1,q2,q3 = x,y,z,w)"

    def facing(b, k):  # body -y axis, body->world
        m = rot(B[b][k], order, True)
        return [-v for v in col(m, 1)]

    # the handover point: the baton position on the row the taker's force first exceeds 5 N
    grasp = next(k for k in range(n) if norm(W["taker"][k][0:3]) > 5.0)
    release = next(k for k in range(grasp, n) if norm(W["giver"][k][0:3]) < 1.0)
    hp = P["baton"][grasp]
    print(f"\n== 6. timeline; taker |F| > 5 N first at row {grasp} (t {grasp / HZ:.3f} s), giver |F| < 1 N after it at row"
          f" {release} (t {release / HZ:.3f} s); baton there: [{hp[0]:+.3f} {hp[1]:+.3f} {hp[2]:+.3f}]")
    print("  t[s]  row | baton xyz             | tR xyz                | tR-baton | v_baton v_gR  v_tR(raw) v_tR(1e) v_tL(1e)"
          " | |F|g  |F|t | head(-y)->handover, ->baton [deg] | chest(-y) horiz->handover")
    for k in list(range(0, 240, 24)) + list(range(240, 480, 6)) + list(range(480, n, 24)) + [n - 1]:
        bv = speed(P["baton"], k)
        gv = speed(P["giver_RHand"], k)
        tv = speed(P["taker_RHand"], k)
        hf = facing("taker_head", k)
        cf = facing("taker_chest", k)
        to_hp = sub(hp, P["taker_head"][k])
        to_b = sub(P["baton"][k], P["taker_head"][k])
        ch = sub(hp, P["taker_chest"][k])
        ch[2] = 0.0
        cfh = [cf[0], cf[1], 0.0]
        b, r = P["baton"][k], P["taker_RHand"][k]
        print(f"  {k / HZ:5.3f} {k:4d} | {b[0]:+.3f} {b[1]:+.3f} {b[2]:+.3f} | {r[0]:+.3f} {r[1]:+.3f} {r[2]:+.3f} |"
              f" {norm(sub(b, r)):.3f}    | {bv:.3f}   {gv:.3f} {tv:.3f}     {fspeed['taker_RHand'][k]:.3f}    "
              f"{fspeed['taker_LHand'][k]:.3f}    | {norm(W['giver'][k][0:3]):5.2f} {norm(W['taker'][k][0:3]):5.2f} |"
              f" {angle_deg(hf, to_hp):5.1f} {angle_deg(hf, to_b):5.1f} | {angle_deg(cfh, ch):5.1f}")
    # baton speed onset: first row after 1 s where the baton speed exceeds thresholds
    for th in (0.05, 0.1, 0.2):
        k0 = next(k for k in range(n) if speed(P["baton"], k) > th and k > 200)
        print(f"  baton speed first > {th} m/s after row 200: row {k0} (t {k0 / HZ:.3f} s)")
    for th in (0.1, 0.2):
        k0 = next(k for k in range(200, n) if speed(P["giver_RHand"], k) > th)
        print(f"  giver RHand speed first > {th} m/s after row 200: row {k0} (t {k0 / HZ:.3f} s)")
    # runs of the filtered right-hand speed below v_max = 0.10 m/s (rows with a defined speed)
    runs, start = [], None
    for k in range(1, n + 1):
        low = k < n and fspeed["taker_RHand"][k] < 0.10
        if low and start is None:
            start = k
        if not low and start is not None:
            runs.append((start, k - 1))
            start = None
    print("  filtered right-hand speed < 0.10 m/s, runs of >= 0.1 s [rows, t]: " + ", ".join(
        f"{a}-{b} ({a / HZ:.3f}-{b / HZ:.3f} s, {b - a + 1} rows)" for a, b in runs if b - a + 1 >= 12))
    # head facing statistics in phases
    for lo, hi, label in [(0, 240, "before reach"), (240, grasp, "giver reach -> grasp"), (grasp, release, "grasp -> release"),
                          (release, n, "after release")]:
        a = [angle_deg(facing("taker_head", k), sub(hp, P["taker_head"][k])) for k in range(lo, hi)]
        ab = [angle_deg(facing("taker_head", k), sub(P["baton"][k], P["taker_head"][k])) for k in range(lo, hi)]
        print(f"  {label:22s} rows {lo}-{hi - 1}: head(-y) to handover point median {median(a):.1f} deg"
              f" (max {max(a):.1f}); to baton median {median(ab):.1f} deg")

    # the representative centres of config/kth-handover-workspace.toml
    centres = {"handover": [0.00, -0.17, 1.10], "assembly-table": [0.26, 0.31, 0.82],
               "tool-storage": [0.65, -0.775, 0.80], "instruction-display": [0.60, 0.825, 1.45]}
    print("\n== 7. head (-y) angle to each calibrated centre r_i [deg]: min / median / max per phase")
    for lo, hi, label in [(0, 254, "before reach onset"), (254, release, "onset -> release"), (release, n, "after release"),
                          (696, n, "baton set down (5.8 s-)")]:
        parts = []
        for name, r in centres.items():
            a = [angle_deg(facing("taker_head", k), sub(r, P["taker_head"][k])) for k in range(lo, hi)]
            parts.append(f"{name} {min(a):.1f}/{median(a):.1f}/{max(a):.1f}")
        print(f"  {label:24s} " + " | ".join(parts))


if __name__ == "__main__":
    timeline()
