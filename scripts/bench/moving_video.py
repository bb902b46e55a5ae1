"""Moving video, side by side: hrc-adapt's landmark pipeline against mediapipe 0.10.21's Python
video mode on the same frames (issue 13, points 2 and 6). Run by scripts/bench/side-by-side and
scripts/models/reference, in the runtime venv of scripts/models/lib.sh (mediapipe 0.10.21 with
its opencv-contrib-python). The frames are written by `assess/examples/moving_video.rs make`
(SIMULATED motion of the real photo data/images/pose_sitting.jpg, lossless PNGs).

  moving_video.py mediapipe <frames dir> <out.json> [--fixture]
      Decodes every PNG first (decoding is timed on its own, not in the loop), then runs
      mediapipe's Pose (complexity 1), FaceMesh and Hands (complexity 1, 2 hands) in video mode
      (static_image_mode=False, smooth_landmarks=False, as scripts/models/reference_tracking.py)
      frame by frame; writes the landmarks [px] and the loop's wall and CPU time (all threads).
      --fixture: the test fixture instead: landmarks rounded to 0.01 px, no timing, and the
      frames' checksums from <frames dir>/frames.json.
  moving_video.py compare <ours.json> <mediapipe.json> [--label L]
      Accuracy of ours against mediapipe's, frame by frame, in the units of the issue's
      tolerances: pose worst landmark / shoulder width (11-12), and nose, shoulders, hips;
      face worst / eye-corner distance (33-263); hands worst / wrist-middle-knuckle length (0-9),
      hands paired by wrist. Then speed: fps (wall) and frames per CPU-second of the loop.
      Prints one JSON line (for the driver) and a readable summary.
"""

import argparse
import json
import math
import pathlib
import statistics
import sys
import time

import cv2


def px(landmarks, w, h):
    return [[p.x * w, p.y * h] for p in landmarks.landmark]


def run_mediapipe(frames_dir, out, fixture):
    import mediapipe as mp

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "models"))
    from reference_tracking import video_mode_solutions

    pngs = sorted(pathlib.Path(frames_dir).glob("*.png"))
    if not pngs:
        sys.exit(f"mediapipe: no .png frames in {frames_dir}")
    t0 = time.perf_counter()
    frames = [cv2.cvtColor(cv2.imread(str(p)), cv2.COLOR_BGR2RGB) for p in pngs]
    decode_s = time.perf_counter() - t0
    pose, face, hands = video_mode_solutions()
    result = []
    per_model = {"pose": 0.0, "face": 0.0, "hands": 0.0}
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k, f in enumerate(frames):
        h, w = f.shape[:2]
        t = time.perf_counter()
        p = pose.process(f)
        per_model["pose"] += time.perf_counter() - t
        t = time.perf_counter()
        fm = face.process(f)
        per_model["face"] += time.perf_counter() - t
        t = time.perf_counter()
        hd = hands.process(f)
        per_model["hands"] += time.perf_counter() - t
        result.append({
            "frame": k,
            "pose": px(p.pose_landmarks, w, h) if p.pose_landmarks else None,
            "face": px(fm.multi_face_landmarks[0], w, h) if fm.multi_face_landmarks else None,
            "hands": [px(x, w, h) for x in (hd.multi_hand_landmarks or [])],
        })
    loop_wall_s, loop_cpu_s = time.perf_counter() - wall0, time.process_time() - cpu0
    if fixture:
        made = json.load(open(pathlib.Path(frames_dir) / "frames.json"))
        if len(made["frames"]) != len(result):
            sys.exit(f"mediapipe: frames.json lists {len(made['frames'])} frames, not {len(result)}")
        rnd = lambda pts: [[round(x, 2), round(y, 2)] for x, y in pts] if pts else None
        for r, m in zip(result, made["frames"]):
            r["fnv1a"] = m["fnv1a"]
            r["pose"], r["face"] = rnd(r["pose"]), rnd(r["face"])
            r["hands"] = [rnd(h) for h in r["hands"]]
        doc = {
            "source": f"mediapipe {mp.__version__} Python solutions in video mode "
                      "(static_image_mode=False, smooth_landmarks=False; Pose complexity 1, "
                      "FaceMesh without refinement, Hands complexity 1, 2 hands), "
                      "scripts/models/reference via scripts/bench/moving_video.py --fixture",
            "frames_made_by": made["made_by"],
            "simulated": made["simulated"],
            "units": "px, rounded to 0.01",
            "frames": result,
        }
        with open(out, "w") as fh:
            json.dump(doc, fh, separators=(",", ":"))
        print(f"mediapipe: fixture of {len(result)} frames in {out}", file=sys.stderr)
        return
    doc = {
        "tool": f"mediapipe {mp.__version__} Python solutions, video mode",
        "input": frames_dir,
        "frames": result,
        "decode_s": decode_s,
        "models_s": per_model,
        "loop_wall_s": loop_wall_s,
        "loop_cpu_s": loop_cpu_s,
    }
    with open(out, "w") as fh:
        json.dump(doc, fh)
    n = len(result)
    print(f"mediapipe: {n} frames, {n / loop_wall_s:.1f} fps wall, {loop_cpu_s:.2f} s CPU",
          file=sys.stderr)


def dist(a, b):
    return math.hypot(a[0] - b[0], a[1] - b[1])


def worst(ours, ref, idx=None):
    idx = range(len(ref)) if idx is None else idx
    return max(dist(ours[i], ref[i]) for i in idx)


def summary(xs):
    if not xs:
        return None
    return {"median": statistics.median(xs), "max": max(xs), "n": len(xs)}


def compare(ours_path, ref_path, label):
    ours = json.load(open(ours_path))
    ref = json.load(open(ref_path))
    if len(ours["frames"]) != len(ref["frames"]):
        sys.exit(f"compare: {len(ours['frames'])} frames against {len(ref['frames'])}")
    pose_worst, core_worst, face_worst, hand_worst = [], [], [], []
    hand_worst_from1 = []
    missing = {"pose": 0, "face": 0, "hands": 0}
    for k, (o, r) in enumerate(zip(ours["frames"], ref["frames"])):
        if r["pose"]:
            if o["pose"]:
                sw = dist(r["pose"][11], r["pose"][12])
                pose_worst.append(worst(o["pose"], r["pose"]) / sw)
                core_worst.append(worst(o["pose"], r["pose"], [0, 11, 12, 23, 24]) / sw)
            else:
                missing["pose"] += 1
        if r["face"]:
            if o["face"]:
                face_worst.append(worst(o["face"], r["face"]) / dist(r["face"][33], r["face"][263]))
            else:
                missing["face"] += 1
        for rh in r["hands"]:
            cand = sorted(o["hands"], key=lambda oh: dist(oh[0], rh[0]))
            if not cand or dist(cand[0][0], rh[0]) > 2 * dist(rh[0], rh[9]):
                missing["hands"] += 1
                continue
            e = worst(cand[0], rh) / dist(rh[0], rh[9])
            hand_worst.append(e)
            if k >= 1:
                hand_worst_from1.append(e)
    n = len(ref["frames"])
    res = {
        "label": label,
        "frames": n,
        "pose_worst_over_shoulder": summary(pose_worst),
        "pose_nose_shoulders_hips_over_shoulder": summary(core_worst),
        "face_worst_over_eye_corners": summary(face_worst),
        "hands_worst_over_wrist_knuckle": summary(hand_worst),
        "hands_worst_from_frame_1": summary(hand_worst_from1),
        "pose_frames_over_8pct": sum(1 for e in pose_worst if e > 0.08),
        "missing_in_ours": missing,
        "ours": {
            "fps_wall": n / ours["loop_wall_s"],
            "frames_per_cpu_s": n / ours["loop_cpu_s"] if ours["loop_cpu_s"] > 0 else None,
            "ms_per_frame_pipeline": 1e3 * ours["pipeline_s"] / n,
            "ms_per_frame_decode_before": 1e3 * ours["decode_s"] / n,
            "ms_per_frame_cues": 1e3 * ours["cues_s"] / n,
            "stages_ms_per_frame": {k: 1e3 * v / n for k, v in ours["stages_s"].items()},
            "runs": ours["runs"],
        },
        "mediapipe": {
            "fps_wall": n / ref["loop_wall_s"],
            "frames_per_cpu_s": n / ref["loop_cpu_s"] if ref["loop_cpu_s"] > 0 else None,
            "ms_per_frame_decode_before": 1e3 * ref["decode_s"] / n,
            "models_ms_per_frame": {k: 1e3 * v / n for k, v in ref["models_s"].items()},
        },
    }
    print(json.dumps(res))
    pct = lambda s: "n/a" if s is None else f"median {100 * s['median']:.1f} %, max {100 * s['max']:.1f} %"
    print(f"[{label}] {n} frames. Accuracy against mediapipe's video mode:", file=sys.stderr)
    print(f"  pose worst landmark / shoulder width: {pct(res['pose_worst_over_shoulder'])}"
          f" ({res['pose_frames_over_8pct']} frames over 8 %)", file=sys.stderr)
    print(f"  pose nose, shoulders, hips: {pct(res['pose_nose_shoulders_hips_over_shoulder'])}",
          file=sys.stderr)
    print(f"  face / eye corners: {pct(res['face_worst_over_eye_corners'])}", file=sys.stderr)
    print(f"  hands / wrist-knuckle: {pct(res['hands_worst_over_wrist_knuckle'])};"
          f" from frame 1: {pct(res['hands_worst_from_frame_1'])}", file=sys.stderr)
    print(f"  missing in ours where mediapipe has one: {missing}", file=sys.stderr)
    o, m = res["ours"], res["mediapipe"]
    print(f"  speed: ours {o['fps_wall']:.1f} fps, {o['frames_per_cpu_s']:.1f} frames/CPU-s;"
          f" mediapipe {m['fps_wall']:.1f} fps, {m['frames_per_cpu_s']:.1f} frames/CPU-s",
          file=sys.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("mediapipe")
    a.add_argument("frames_dir")
    a.add_argument("out")
    a.add_argument("--fixture", action="store_true")
    a = sub.add_parser("compare")
    a.add_argument("ours")
    a.add_argument("ref")
    a.add_argument("--label", default="")
    args = ap.parse_args()
    if args.cmd == "mediapipe":
        run_mediapipe(args.frames_dir, args.out, args.fixture)
    else:
        compare(args.ours, args.ref, args.label)


if __name__ == "__main__":
    main()
