"""Reference landmarks from the official mediapipe Python package on the test photos.

Usage (in the runtime venv, which has mediapipe; scripts/models/reference sets it up and runs this):
    python reference_landmarks.py IMAGES_DIR OUT.json

For each photo (decoded with cv2, BGR -> RGB) it runs the legacy solutions with static_image_mode
and min_detection_confidence 0.5 (SOLUTIONS below) and writes, compactly:

  pose   list of 0 or 1: landmarks 33 x [x_px, y_px, z, visibility, presence],
         world 33 x [x, y, z] (metres, hip-centred)
  hands  list of 0..2: landmarks 21 x [x_px, y_px, z], world 21 x [x, y, z] (metres),
         handedness {label, score, index} as mediapipe reports it (it assumes a mirrored,
         selfie-view image, so on an unmirrored photo 'Left' is the person's right hand)
  faces  list of 0..2: landmarks 468 x [x_px, y_px, z]

x_px = normalised x * width, y_px = normalised y * height (pixel units, origin at the top-left
corner of the top-left pixel); z is mediapipe's normalised z, unscaled (roughly the scale of
normalised x: multiply by width for pixels). Pixels are rounded to 0.01, the rest to 1e-4.

Intermediate results come from the same official solution objects, with extra output streams of
their graphs observed (pose_detection, pose_rect_from_detection; palm_detections,
hand_rects_from_palm_detections; face_detections, face_rects_from_detections). Observing a stream
changes nothing in the graph; the script checks that by running a plain instance too and
requiring identical landmarks. Detections: score, box [x_px, y_px, w_px, h_px] and keypoints
[[x_px, y_px], ...]; rects: [cx_px, cy_px, w_px, h_px, rotation_rad].
"""

import json
import os
import sys

import cv2
import mediapipe as mp
from mediapipe.python.solution_base import SolutionBase

IMAGES = [
    "business-person.png",
    "pose_sitting.jpg",
    "two_children.jpeg",
    "thumbs_up_two.jpg",
    "hand_thumb_up.jpg",
]

SOLUTIONS = {
    "pose": (
        "mp.solutions.pose.Pose",
        dict(static_image_mode=True, model_complexity=1, min_detection_confidence=0.5),
        ["pose_detection", "pose_rect_from_detection"],
    ),
    "hands": (
        "mp.solutions.hands.Hands",
        dict(static_image_mode=True, max_num_hands=2, model_complexity=1, min_detection_confidence=0.5),
        ["palm_detections", "hand_rects_from_palm_detections"],
    ),
    "faces": (
        "mp.solutions.face_mesh.FaceMesh",
        dict(static_image_mode=True, max_num_faces=2, refine_landmarks=False, min_detection_confidence=0.5),
        ["face_detections", "face_rects_from_detections"],
    ),
}
CLASSES = {
    "mp.solutions.pose.Pose": mp.solutions.pose.Pose,
    "mp.solutions.hands.Hands": mp.solutions.hands.Hands,
    "mp.solutions.face_mesh.FaceMesh": mp.solutions.face_mesh.FaceMesh,
}


def with_extra_outputs(cls, extra, **kwargs):
    """Construct the official solution class, adding output streams to observe."""
    original = SolutionBase.__init__

    def patched(self, *args, outputs=None, **kw):
        original(self, *args, outputs=list(outputs or []) + extra, **kw)

    SolutionBase.__init__ = patched
    try:
        return cls(**kwargs)
    finally:
        SolutionBase.__init__ = original


def r2(v):
    return round(float(v), 2)


def r4(v):
    return round(float(v), 4)


def norm_landmarks(lms, w, h, extra=()):
    return [[r2(p.x * w), r2(p.y * h), r4(p.z)] + [r4(getattr(p, a)) for a in extra] for p in lms.landmark]


def world_landmarks(lms):
    return [[r4(p.x), r4(p.y), r4(p.z)] for p in lms.landmark]


def detection(d, w, h):
    loc = d.location_data
    bb = loc.relative_bounding_box
    return {
        "score": r4(d.score[0]) if d.score else None,
        "box": [r2(bb.xmin * w), r2(bb.ymin * h), r2(bb.width * w), r2(bb.height * h)],
        "keypoints": [[r2(k.x * w), r2(k.y * h)] for k in loc.relative_keypoints],
    }


def rect(r, w, h):
    return [r2(r.x_center * w), r2(r.y_center * h), r2(r.width * w), r2(r.height * h), r4(r.rotation)]


def as_list(v):
    if v is None:
        return []
    return list(v) if isinstance(v, (list, tuple)) else [v]


def landmark_lists(key, res):
    if key == "pose":
        return as_list(res.pose_landmarks)
    if key == "hands":
        return as_list(res.multi_hand_landmarks)
    return as_list(res.multi_face_landmarks)


def main(images_dir, out_path):
    out = {
        "generator": "scripts/models/reference_landmarks.py",
        "mediapipe_version": mp.__version__,
        "opencv_version": cv2.__version__,
        "solutions": {k: {"class": c, "options": o} for k, (c, o, _) in SOLUTIONS.items()},
        "units": {
            "landmarks": "x_px, y_px: normalised x * width, y * height; z: mediapipe's normalised z, unscaled",
            "pose": "landmarks 33 x [x_px, y_px, z, visibility, presence]; world 33 x [x, y, z] metres",
            "hands": "landmarks 21 x [x_px, y_px, z]; world 21 x [x, y, z] metres; handedness as mediapipe reports it (mirrored-image convention)",
            "faces": "landmarks 468 x [x_px, y_px, z]",
            "detections": "score; box [x_px, y_px, w_px, h_px]; keypoints [[x_px, y_px], ...]",
            "rects": "[cx_px, cy_px, w_px, h_px, rotation_rad]",
        },
        "images": [],
    }
    plain = {k: CLASSES[c](**o) for k, (c, o, _) in SOLUTIONS.items()}
    observed = {k: with_extra_outputs(CLASSES[c], extra, **o) for k, (c, o, extra) in SOLUTIONS.items()}

    for name in IMAGES:
        bgr = cv2.imread(os.path.join(images_dir, name), cv2.IMREAD_COLOR)
        if bgr is None:
            raise SystemExit(f"cannot read {name}")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        h, w = rgb.shape[:2]
        entry = {"file": name, "width": w, "height": h}
        results = {}
        for key in SOLUTIONS:
            a = plain[key].process(rgb)
            b = observed[key].process(rgb)
            la, lb = landmark_lists(key, a), landmark_lists(key, b)
            if [x.SerializeToString() for x in la] != [x.SerializeToString() for x in lb]:
                raise SystemExit(f"{name}/{key}: observing intermediate streams changed the landmarks")
            results[key] = b

        res = results["pose"]
        entry["pose"] = []
        if res.pose_landmarks is not None:
            entry["pose"].append(
                {
                    "landmarks": norm_landmarks(res.pose_landmarks, w, h, ("visibility", "presence")),
                    "world": world_landmarks(res.pose_world_landmarks),
                }
            )
        res = results["hands"]
        entry["hands"] = []
        for lms, world, hd in zip(
            as_list(res.multi_hand_landmarks), as_list(res.multi_hand_world_landmarks), as_list(res.multi_handedness)
        ):
            c = hd.classification[0]
            entry["hands"].append(
                {
                    "handedness": {"label": c.label, "score": r4(c.score), "index": c.index},
                    "landmarks": norm_landmarks(lms, w, h),
                    "world": world_landmarks(world),
                }
            )
        res = results["faces"]
        entry["faces"] = [{"landmarks": norm_landmarks(lms, w, h)} for lms in as_list(res.multi_face_landmarks)]

        entry["intermediate"] = {
            "pose_detection": [detection(d, w, h) for d in as_list(results["pose"].pose_detection)],
            "pose_rect_from_detection": [rect(r, w, h) for r in as_list(results["pose"].pose_rect_from_detection)],
            "palm_detections": [detection(d, w, h) for d in as_list(results["hands"].palm_detections)],
            "hand_rects_from_palm_detections": [
                rect(r, w, h) for r in as_list(results["hands"].hand_rects_from_palm_detections)
            ],
            "face_detections": [detection(d, w, h) for d in as_list(results["faces"].face_detections)],
            "face_rects_from_detections": [rect(r, w, h) for r in as_list(results["faces"].face_rects_from_detections)],
        }
        out["images"].append(entry)
        print(
            f"{name}: {w}x{h}, pose {len(entry['pose'])}, hands {len(entry['hands'])} "
            f"{[x['handedness']['label'] for x in entry['hands']]}, faces {len(entry['faces'])}; "
            f"detections: pose {len(entry['intermediate']['pose_detection'])}, "
            f"palm {len(entry['intermediate']['palm_detections'])}, face {len(entry['intermediate']['face_detections'])}"
        )

    os.makedirs(os.path.dirname(os.path.abspath(out_path)), exist_ok=True)
    with open(out_path, "w") as f:
        # One image entry per block of lines, one landmark per line would be large; keep it compact.
        json.dump(out, f, separators=(",", ":"))
        f.write("\n")
    print(f"{out_path}: {os.path.getsize(out_path)} bytes")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2])
