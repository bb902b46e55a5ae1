"""Check each converted ONNX model against its .tflite original.

Usage (in the runtime venv: tflite-runtime 2.14.0, onnxruntime 1.31.1, opencv from mediapipe):
    python check_onnx.py SOURCES_DIR MODELS_DIR IMAGES_DIR [--fixture JSON] [--readme README.md]

SOURCES_DIR is where extract_sources.py put the original .tflite files and sources.json. For each
model two inputs go through the TFLite interpreter (the original, unfolded .tflite, with its
default XNNPACK delegate as MediaPipe runs it) and through onnxruntime (CPU, default graph
optimisations) on models/<name>.onnx:
  random  uniform noise over the model's input value range (numpy seed 0);
  photo   one of the test photos scaled to the input range: detectors get the whole photo
          letterboxed with black bars; landmark models get the rotated square ROI that the
          official mediapipe package derived from its detection (from the reference fixture
          assess/tests/fixtures/vision/mediapipe_reference.json), resampled as in
          MediaPipe's ImageToTensorCalculator (bilinear, replicated border).
It prints the largest absolute difference per output and, on the photo, the score a pipeline
would threshold (so a wrong input range would show). For the landmark models it also projects
the ONNX landmarks back through the ROI (x_img = cx + cos r (x/S - 1/2) w - sin r (y/S - 1/2) h,
y_img = cy + sin r (x/S - 1/2) w + cos r (y/S - 1/2) h) and reports their median distance to
the official landmarks, which checks the decoding described in models/README.md. The official
ones come from the full models (model_complexity=1) and, for pose, after MediaPipe's heatmap
refinement, which this check does not apply; so expect more for pose and for the lite models. With --readme, the generated table in that
file (between the check_onnx markers) is replaced. Exits 1 if any difference exceeds TOLERANCE.
"""

import argparse
import json
import os
import sys

import cv2
import numpy as np
import onnxruntime as ort
import tflite_runtime
from tflite_runtime.interpreter import Interpreter

# Input value range of each model, as MediaPipe's graphs feed it (ImageToTensorCalculator's
# output_tensor_float_range in pose_detection_cpu, pose_landmark_by_roi_cpu, palm_detection_cpu,
# hand_landmark_cpu, face_landmark_cpu; FaceDetection's [-1, 1] for face_detection_short_range).
INPUT_RANGE = {
    "pose_detection": (-1.0, 1.0),
    "pose_landmark_full": (0.0, 1.0),
    "pose_landmark_lite": (0.0, 1.0),
    "palm_detection_full": (0.0, 1.0),
    "palm_detection_lite": (0.0, 1.0),
    "hand_landmark_full": (0.0, 1.0),
    "hand_landmark_lite": (0.0, 1.0),
    "face_detection_short_range": (-1.0, 1.0),
    "face_landmark": (0.0, 1.0),
}
# Photo for each model and which reference ROI to crop (None: the whole photo, letterboxed).
PHOTO = {
    "pose_detection": ("pose_sitting.jpg", None),
    "pose_landmark_full": ("pose_sitting.jpg", "pose"),
    "pose_landmark_lite": ("pose_sitting.jpg", "pose"),
    "palm_detection_full": ("hand_thumb_up.jpg", None),
    "palm_detection_lite": ("hand_thumb_up.jpg", None),
    "hand_landmark_full": ("hand_thumb_up.jpg", "hands"),
    "hand_landmark_lite": ("hand_thumb_up.jpg", "hands"),
    "face_detection_short_range": ("two_children.jpeg", None),
    "face_landmark": ("business-person.png", "faces"),
}
# Border for ROIs that leave the image; replicate matched the official pose landmarks better than zero.
BORDER = cv2.BORDER_REPLICATE
ROI_KEY = {"pose": "pose_rect_from_detection", "hands": "hand_rects_from_palm_detections", "faces": "face_rects_from_detections"}
# Landmark output index, values per landmark and number of landmarks to compare with the reference.
LANDMARKS = {"pose": (0, 5, 33), "hands": (0, 3, 21), "faces": (0, 3, 468)}
# A converted model fails the check if max |onnx - tflite| > TOLERANCE * max(1, max |tflite|).
TOLERANCE = 1e-3


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-np.clip(np.asarray(x, dtype=np.float64), -100.0, 100.0)))


def score_summary(name, outs):
    """The score a pipeline thresholds, from the ONNX outputs on the photo (see models/README.md)."""
    if "detection" in name:
        return f"max detection score sigmoid(logit) = {float(sigmoid(outs[1]).max()):.3f}"
    if name.startswith("pose_landmark"):
        return f"pose flag = {float(outs[1].ravel()[0]):.3f}"
    if name.startswith("hand_landmark"):
        return f"hand flag = {float(outs[1].ravel()[0]):.3f}, handedness = {float(outs[2].ravel()[0]):.3f}"
    if name == "face_landmark":
        return f"face flag sigmoid(logit) = {float(sigmoid(outs[1]).ravel()[0]):.3f}"
    return ""


def load_photo(path):
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        raise SystemExit(f"cannot read {path}")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def roi_input(img, rect, size, lo, hi):
    """Resample the rotated square ROI [cx, cy, w, h, r] (image pixels) to the model input."""
    cx, cy, w, h, r = rect
    c, s = np.cos(r), np.sin(r)
    a, b = w / size, h / size
    # Continuous source point of output pixel centre (u + 1/2, v + 1/2); OpenCV puts pixel centres
    # at integer coordinates, hence the final - 0.5.
    m = np.array(
        [
            [c * a, -s * b, cx + c * (0.5 * a - w / 2) - s * (0.5 * b - h / 2) - 0.5],
            [s * a, c * b, cy + s * (0.5 * a - w / 2) + c * (0.5 * b - h / 2) - 0.5],
        ]
    )
    x = cv2.warpAffine(
        img, m, (size, size), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=BORDER
    ).astype(np.float32) / 255.0
    return (lo + x * (hi - lo))[None].astype(np.float32)


def letterbox_input(img, size, lo, hi):
    """Scale to fit, centre, black bars."""
    s = min(size / img.shape[1], size / img.shape[0])
    rw, rh = max(1, round(img.shape[1] * s)), max(1, round(img.shape[0] * s))
    x = np.zeros((size, size, 3), dtype=np.float32)
    ox, oy = (size - rw) // 2, (size - rh) // 2
    x[oy : oy + rh, ox : ox + rw] = cv2.resize(img, (rw, rh), interpolation=cv2.INTER_AREA).astype(np.float32) / 255.0
    return (lo + x * (hi - lo))[None].astype(np.float32)


def project(outs, kind, rect, size):
    """ONNX landmarks (input pixels) -> image pixels through the ROI."""
    index, per, n = LANDMARKS[kind]
    lm = np.asarray(outs[index], dtype=np.float64).reshape(-1, per)[:n, :2] / size - 0.5
    cx, cy, w, h, r = rect
    c, s = np.cos(r), np.sin(r)
    return np.stack([cx + c * lm[:, 0] * w - s * lm[:, 1] * h, cy + s * lm[:, 0] * w + c * lm[:, 1] * h], 1)


def run_tflite(path, x):
    it = Interpreter(model_path=path, num_threads=1)
    it.allocate_tensors()
    it.set_tensor(it.get_input_details()[0]["index"], x)
    it.invoke()
    return [it.get_tensor(d["index"]).copy() for d in it.get_output_details()]


def run_onnx(sess, x):
    return sess.run(None, {sess.get_inputs()[0].name: x})


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sources")
    ap.add_argument("models")
    ap.add_argument("images")
    ap.add_argument("--fixture")
    ap.add_argument("--readme")
    args = ap.parse_args()

    with open(os.path.join(args.sources, "sources.json")) as f:
        names = list(json.load(f)["models"])
    fixture = {}
    if args.fixture and os.path.exists(args.fixture):
        with open(args.fixture) as f:
            fixture = {e["file"]: e for e in json.load(f)["images"]}

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    rows = []
    failed = []
    for name in names:
        tfl = os.path.join(args.sources, name + ".tflite")
        onx = os.path.join(args.models, name + ".onnx")
        sess = ort.InferenceSession(onx, opts, providers=["CPUExecutionProvider"])
        inp = sess.get_inputs()[0]
        _, h, w, _ = inp.shape
        lo, hi = INPUT_RANGE[name]
        photo, kind = PHOTO[name]
        img = load_photo(os.path.join(args.images, photo))
        rect = None
        if kind:
            rects = fixture.get(photo, {}).get("intermediate", {}).get(ROI_KEY[kind], [])
            if not rects:
                raise SystemExit(f"{name}: no {ROI_KEY[kind]} for {photo} in the fixture (run scripts/models/reference)")
            rect = rects[0]
        inputs = {
            "random": np.random.default_rng(0).uniform(lo, hi, (1, h, w, 3)).astype(np.float32),
            "photo": letterbox_input(img, h, lo, hi) if rect is None else roi_input(img, rect, h, lo, hi),
        }
        outs = {k: (run_tflite(tfl, x), run_onnx(sess, x)) for k, x in inputs.items()}
        out_names = [o.name for o in sess.get_outputs()]
        for i, oname in enumerate(out_names):
            diffs = []
            for k in ("random", "photo"):
                ref, got = outs[k][0][i], outs[k][1][i]
                if ref.shape != got.shape:
                    failed.append(f"{name}/{oname}: shape {got.shape} != tflite {ref.shape}")
                    diffs.append((float("nan"), float("nan")))
                    continue
                d = float(np.abs(ref - got).max())
                scale = float(np.abs(ref).max())
                if d > TOLERANCE * max(1.0, scale):
                    failed.append(f"{name}/{oname} ({k}): max |diff| {d:.3g} vs max |tflite| {scale:.3g}")
                diffs.append((d, scale))
            rows.append((name, oname, diffs))
        crop = f"the reference {ROI_KEY[kind]}[0]" if rect is not None else "whole photo, letterboxed"
        summary = score_summary(name, outs["photo"][1])
        if rect is not None:
            got = project(outs["photo"][1], kind, rect, h)
            # The reference entity this ROI belongs to: the one nearest to the projected landmarks.
            errs = [
                float(np.median(np.linalg.norm(got - np.asarray(e["landmarks"])[:, :2], axis=1)))
                for e in fixture[photo][kind]
            ]
            if errs:
                summary += f"; landmarks projected through the ROI: median {min(errs):.2f} px from the official ones"
        rows.append((name, None, f"{photo} ({crop}): {summary}"))

    lines = [
        "| model | output | max abs diff, random input | max abs diff, photo | max abs value (photo) |",
        "|---|---|---|---|---|",
    ]
    notes = []
    for name, oname, d in rows:
        if oname is None:
            notes.append(f"- `{name}` on {d}")
            continue
        (dr, _), (dp, sp) = d
        lines.append(f"| `{name}` | `{oname}` | {dr:.2e} | {dp:.2e} | {sp:.3g} |")
    text = "\n".join(lines) + "\n\nScores on the photo input (ONNX outputs):\n\n" + "\n".join(notes) + "\n"
    print(text)
    if failed:
        print("FAILED:\n  " + "\n  ".join(failed), file=sys.stderr)

    if args.readme:
        begin, end = "<!-- check_onnx: begin -->", "<!-- check_onnx: end -->"
        with open(args.readme) as f:
            readme = f.read()
        if begin not in readme or end not in readme:
            raise SystemExit(f"{args.readme}: markers {begin} / {end} not found")
        head, rest = readme.split(begin, 1)
        _, tail = rest.split(end, 1)
        versions = f"onnxruntime {ort.__version__}, tflite-runtime {tflite_runtime.__version__}"
        with open(args.readme, "w") as f:
            f.write(f"{head}{begin}\n_Generated by `scripts/models/check_onnx.py` ({versions})._\n\n{text}{end}{tail}")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
