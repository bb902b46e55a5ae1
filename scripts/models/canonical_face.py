"""Write the 468 canonical 3-D face points as CSV (index,x,y,z; centimetres).

Usage (in the runtime venv, for mediapipe's protobuf classes):
    python canonical_face.py geometry_pipeline_metadata_landmarks.binarypb OUT.csv

The input is MediaPipe's face-geometry pipeline metadata (a GeometryPipelineMetadata protobuf, as
shipped in npm @mediapipe/face_mesh). Its canonical_mesh is built by MediaPipe from
mediapipe/modules/face_geometry/data/canonical_face_model.obj: the vertex buffer holds, per
vertex in the .obj's 'v' order, x, y, z (cm) followed by the texture coordinates u, v. Only
x, y, z are written, rounded to 6 decimals as in the .obj (the values are float32).
"""

import sys

import numpy as np
from mediapipe.modules.face_geometry.protos import geometry_pipeline_metadata_pb2 as gpm
from mediapipe.modules.face_geometry.protos import mesh_3d_pb2

N_POINTS = 468


def main(src, out):
    meta = gpm.GeometryPipelineMetadata()
    with open(src, "rb") as f:
        meta.ParseFromString(f.read())
    mesh = meta.canonical_mesh
    if mesh.vertex_type != mesh_3d_pb2.Mesh3d.VERTEX_PT:
        raise SystemExit(f"{src}: expected VERTEX_PT (x,y,z,u,v) vertices, got {mesh.vertex_type}")
    v = np.asarray(mesh.vertex_buffer, dtype=np.float32)
    if v.size != N_POINTS * 5:
        raise SystemExit(f"{src}: vertex buffer has {v.size} values, expected {N_POINTS}x5")
    xyz = v.reshape(N_POINTS, 5)[:, :3]
    with open(out, "w") as f:
        f.write("index,x,y,z\n")
        for i, (x, y, z) in enumerate(xyz):
            # '+ 0.0' turns -0.0 into 0.0, as the .obj writes it.
            f.write(f"{i},{round(float(x), 6) + 0.0:.6f},{round(float(y), 6) + 0.0:.6f},{round(float(z), 6) + 0.0:.6f}\n")
    print(f"{out}: {N_POINTS} points, x {xyz[:, 0].min():.3f}..{xyz[:, 0].max():.3f} cm")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    main(sys.argv[1], sys.argv[2])
