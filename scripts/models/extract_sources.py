"""Take the MediaPipe model files out of the downloaded packages (standard library only).

Usage: python extract_sources.py DOWNLOADS_DIR OUT_DIR

DOWNLOADS_DIR holds the pinned packages that scripts/models/convert fetched:
  mediapipe-0.10.21-*.whl                  (PyPI)
  mediapipe-pose-0.5.1675469404.tgz        (npm @mediapipe/pose)
  mediapipe-face_mesh-0.4.1657299874.tgz   (npm @mediapipe/face_mesh)

OUT_DIR receives <model>.tflite for each model in MODELS, the Apache-2.0 LICENSE from the wheel,
geometry_pipeline_metadata_landmarks.binarypb (the canonical face mesh) and sources.json, which
records for every extracted file the package it came from, its path there and both SHA-256s.
"""

import glob
import hashlib
import json
import os
import re
import sys
import tarfile
import zipfile

WHEEL_GLOB = "mediapipe-0.10.21-*.whl"
NPM_POSE = "mediapipe-pose-0.5.1675469404.tgz"
NPM_FACE_MESH = "mediapipe-face_mesh-0.4.1657299874.tgz"

# model name -> (package key, path inside the package)
MODELS = {
    "pose_detection": ("wheel", "mediapipe/modules/pose_detection/pose_detection.tflite"),
    "pose_landmark_full": ("wheel", "mediapipe/modules/pose_landmark/pose_landmark_full.tflite"),
    "pose_landmark_lite": ("npm_pose", "package/pose_landmark_lite.tflite"),
    "palm_detection_full": ("wheel", "mediapipe/modules/palm_detection/palm_detection_full.tflite"),
    "palm_detection_lite": ("wheel", "mediapipe/modules/palm_detection/palm_detection_lite.tflite"),
    "hand_landmark_full": ("wheel", "mediapipe/modules/hand_landmark/hand_landmark_full.tflite"),
    "hand_landmark_lite": ("wheel", "mediapipe/modules/hand_landmark/hand_landmark_lite.tflite"),
    "face_detection_short_range": (
        "wheel",
        "mediapipe/modules/face_detection/face_detection_short_range.tflite",
    ),
    "face_landmark": ("wheel", "mediapipe/modules/face_landmark/face_landmark.tflite"),
}
LICENSE_MEMBER = "mediapipe-0.10.21.dist-info/LICENSE"
# Inside @mediapipe/face_mesh, the files of the WebAssembly build are packed into one .data file;
# the loader script lists each file's byte range.
GEOMETRY_NAME = "/third_party/mediapipe/modules/face_geometry/data/geometry_pipeline_metadata_landmarks.binarypb"
PACKED_DATA = "package/face_mesh_solution_packed_assets.data"
PACKED_LOADER = "package/face_mesh_solution_packed_assets_loader.js"


def sha256(data):
    return hashlib.sha256(data).hexdigest()


def file_sha256(path):
    with open(path, "rb") as f:
        return sha256(f.read())


def main(downloads, out):
    os.makedirs(out, exist_ok=True)
    wheels = sorted(glob.glob(os.path.join(downloads, WHEEL_GLOB)))
    if len(wheels) != 1:
        raise SystemExit(f"expected one {WHEEL_GLOB} in {downloads}, found {wheels}")
    packages = {
        "wheel": ("PyPI mediapipe==0.10.21", wheels[0]),
        "npm_pose": ("npm @mediapipe/pose@0.5.1675469404", os.path.join(downloads, NPM_POSE)),
        "npm_face_mesh": (
            "npm @mediapipe/face_mesh@0.4.1657299874",
            os.path.join(downloads, NPM_FACE_MESH),
        ),
    }
    readers = {}
    with zipfile.ZipFile(wheels[0]) as whl:
        readers["wheel"] = {n: whl.read(n) for n in whl.namelist() if n.endswith(".tflite") or n == LICENSE_MEMBER}
    for key in ("npm_pose", "npm_face_mesh"):
        with tarfile.open(packages[key][1]) as tgz:
            readers[key] = {
                m.name: tgz.extractfile(m).read()
                for m in tgz.getmembers()
                if m.isfile() and (m.name.endswith(".tflite") or m.name in (PACKED_DATA, PACKED_LOADER))
            }

    def record(key, member, data, out_name):
        path = os.path.join(out, out_name)
        with open(path, "wb") as f:
            f.write(data)
        label, archive = packages[key]
        return {
            "file": out_name,
            "package": label,
            "archive": os.path.basename(archive),
            "archive_sha256": file_sha256(archive),
            "member": member,
            "sha256": sha256(data),
            "bytes": len(data),
        }

    sources = {"models": {}, "files": {}}
    for name, (key, member) in MODELS.items():
        if member not in readers[key]:
            raise SystemExit(f"{member} not found in {packages[key][1]}")
        sources["models"][name] = record(key, member, readers[key][member], name + ".tflite")

    sources["files"]["LICENSE"] = record("wheel", LICENSE_MEMBER, readers["wheel"][LICENSE_MEMBER], "LICENSE")

    loader = readers["npm_face_mesh"][PACKED_LOADER].decode("utf-8")
    m = re.search(r'"filename":\s*"' + re.escape(GEOMETRY_NAME) + r'",\s*"start":\s*(\d+),\s*"end":\s*(\d+)', loader)
    if not m:
        raise SystemExit(f"{GEOMETRY_NAME} not listed in {PACKED_LOADER}")
    start, end = int(m.group(1)), int(m.group(2))
    data = readers["npm_face_mesh"][PACKED_DATA][start:end]
    rec = record("npm_face_mesh", f"{PACKED_DATA} bytes {start}..{end} ({GEOMETRY_NAME})", data, "geometry_pipeline_metadata_landmarks.binarypb")
    sources["files"]["geometry_pipeline_metadata_landmarks.binarypb"] = rec

    with open(os.path.join(out, "sources.json"), "w") as f:
        json.dump(sources, f, indent=1)
    for name, r in sources["models"].items():
        print(f"{name}: {r['package']} {r['member']} sha256 {r['sha256'][:16]}")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2])
