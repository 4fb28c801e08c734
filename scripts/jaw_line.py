"""Derive the template's jaw line from the landmark detector (``template.features.JAW_POINTS``).

    python scripts/jaw_line.py [--resolution 1]

The detector draws the lower face oval (``fit.landmarks.CURVE_INDICES["jaw_line"]``) on the
sides at the face's silhouette and under the chin some millimetres above it. The model's
``jaw_line`` must mean the same points, or the pose pass tips the head to lay one on the other.
This renders the built-in head from the front at rest, runs the detector, and takes for each of
its jaw points the skin the camera sees there: of the front-facing skin vertices projecting
within 2 px of it, the nearest to the camera, or the front-facing vertex projecting nearest
where none does (a point on the silhouette). Prints the points (m) of one side from the cheek to
the chin's middle, the two sides averaged, for ``JAW_POINTS``. Needs mitsuba and the
detector (``pip install -e .[landmarks]``).
"""
import argparse

import numpy as np

import invface
from invface.fit.landmarks import curves_from_landmarks, detect_face
from invface.io.images import linear_to_srgb
from invface.mesh.triangles import vertex_normals
from invface.render.camera import Camera
from invface.render.synthetic import render_plate, skin_albedo, studio_light

NEAR_PX = 2.0


def jaw_vertices(model, camera):
    """(the model's surface at rest (V, 3) m, vertex ids (17,) of the skin under the detector's
    jaw points on a front render of it)."""
    p = model.parameters({})
    X = model.surface_model("blendshape").surface(p)
    img, _ = render_plate(model, X, camera, studio_light(), skin_albedo(model), parts_x=model.parts_positions(p),
                          spp=16)
    pts, _ = detect_face(linear_to_srgb(img), name="template render")
    n = vertex_normals(X, model.triangles)
    front = np.flatnonzero(np.einsum("ij,ij->i", n, camera.center - X) > 0)
    uv = camera.project(X[front])[0]
    out = []
    for q in curves_from_landmarks(pts)["jaw_line"]:
        d = np.linalg.norm(uv - q, axis=1)
        near = np.flatnonzero(d < NEAR_PX)
        out.append(front[near[np.argmax(X[front[near], 2])]] if len(near) else front[np.argmin(d)])
    return X, np.array(out)


def main(resolution):
    model = invface.template.build(resolution)
    X, ids = jaw_vertices(model, Camera.front_view(512, 512))
    P = X[ids]
    if P[0, 0] > P[-1, 0]:
        P = P[::-1]                                         # from the actor's right (-X) to the left
    half = len(P) // 2
    left, right = P[half:][::-1], P[:half + 1] * [-1, 1, 1]  # each from the cheek to the chin, as +X
    side = (left + right) / 2
    side[-1, 0] = 0.0                                       # the chin's middle on the midline
    print("JAW_POINTS = [" + ", ".join(f"({x:.4f}, {y:.4f}, {z:.4f})" for x, y, z in side) + "]")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=float, default=1.0)
    main(ap.parse_args().resolution)
