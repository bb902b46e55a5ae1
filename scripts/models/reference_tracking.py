"""Reference landmarks of the official mediapipe 0.10.21 solutions in *video* (tracking) mode.

The "video" is data/images/pose_sitting.jpg panned right by 3 px per frame for 12 frames
(frame k: black columns [0, 3k), then the photo's columns [0, w - 3k)), fed to one solution
instance per model with static_image_mode=False, so mediapipe tracks ROIs from landmarks as
`assess::vision::pipeline` does in `Mode::Tracking`. Landmark smoothing is switched off
(smooth_landmarks=False) because our pipeline leaves smoothing to the cue stage.

Usage: reference_tracking.py <images dir> <out.json>
"""

import json
import sys

import cv2
import mediapipe as mp
import numpy as np

FRAMES = 12
STEP_PX = 3


def frames(path):
    img = cv2.cvtColor(cv2.imread(path), cv2.COLOR_BGR2RGB)
    h, w = img.shape[:2]
    for k in range(FRAMES):
        d = STEP_PX * k
        f = np.zeros_like(img)
        f[:, d:] = img[:, : w - d]
        yield f


def px(landmarks, w, h, extra=False):
    out = []
    for p in landmarks.landmark:
        row = [round(p.x * w, 3), round(p.y * h, 3), round(p.z, 5)]
        if extra:
            row += [round(p.visibility, 4)]
        out.append(row)
    return out


def video_mode_solutions():
    """mediapipe's Pose (complexity 1, landmark smoothing off), FaceMesh (no refinement) and
    Hands (complexity 1, 2 hands) in video mode: the configuration of every video-mode
    reference (also scripts/bench/moving_video.py)."""
    pose = mp.solutions.pose.Pose(static_image_mode=False, model_complexity=1,
                                  smooth_landmarks=False, min_detection_confidence=0.5,
                                  min_tracking_confidence=0.5)
    face = mp.solutions.face_mesh.FaceMesh(static_image_mode=False, max_num_faces=1,
                                           refine_landmarks=False, min_detection_confidence=0.5,
                                           min_tracking_confidence=0.5)
    hands = mp.solutions.hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=1,
                                     min_detection_confidence=0.5, min_tracking_confidence=0.5)
    return pose, face, hands


def main(images, out_path):
    path = f"{images}/pose_sitting.jpg"
    pose, face, hands = video_mode_solutions()
    result = []
    for k, f in enumerate(frames(path)):
        h, w = f.shape[:2]
        p = pose.process(f)
        fm = face.process(f)
        hd = hands.process(f)
        result.append({
            "frame": k,
            "pose": px(p.pose_landmarks, w, h, extra=True) if p.pose_landmarks else None,
            "face": px(fm.multi_face_landmarks[0], w, h) if fm.multi_face_landmarks else None,
            "hands": [px(x, w, h) for x in (hd.multi_hand_landmarks or [])],
        })
    doc = {
        "generator": "scripts/models/reference_tracking.py",
        "mediapipe_version": mp.__version__,
        "video": {"image": "pose_sitting.jpg", "frames": FRAMES, "pan_px_per_frame": STEP_PX},
        "options": {"static_image_mode": False, "model_complexity": 1, "smooth_landmarks": False,
                    "max_num_hands": 2, "max_num_faces": 1, "refine_landmarks": False},
        "units": "x_px, y_px, z (mediapipe normalised z)[, visibility]",
        "frames": result,
    }
    with open(out_path, "w") as fh:
        json.dump(doc, fh, separators=(",", ":"))
        fh.write("\n")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
