"""Red refinement of the flesh mesh (mesh.refine, morph.refine)."""
import numpy as np

from invface.mesh.refine import subdivide
from invface.mesh.tets import boundary_faces, face_use, quality_summary, signed_volumes
from invface.morph.refine import refine
from invface.sim.quasistatic import Simulator


def test_subdivide_conforms_and_keeps_volume_and_shape():
    rng = np.random.default_rng(0)
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]], float) + 0.05 * rng.normal(size=(5, 3))
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    tets[signed_volumes(X, tets) < 0, 2:] = tets[signed_volumes(X, tets) < 0, 2:][:, ::-1]
    X2, t2, edges = subdivide(X, tets)
    assert len(t2) == 16 and len(edges) == 9 and len(X2) == 14
    v = signed_volumes(X2, t2)
    assert np.all(v > 0) and np.isclose(v.sum(), signed_volumes(X, tets).sum(), rtol=1e-12)
    # children of each parent fill it: the 8 volumes sum to the parent's
    assert np.allclose(v.reshape(2, 8).sum(1), signed_volumes(X, tets))
    # conforming: no face used more than twice; 8 inner faces per parent (4 corner-octahedron,
    # 4 around the octahedron's diagonal), and the shared face cut into 4 shared faces
    _, use = face_use(t2)
    assert use.max() == 2 and (use == 2).sum() == 2 * (2 * 8 + 4)
    # the boundary is the old boundary cut in four
    assert len(boundary_faces(t2)[0]) == 4 * len(boundary_faces(tets)[0])
    # the shortest-diagonal split keeps the shapes: min dihedral at least 0.4x the parents'
    assert quality_summary(X2, t2)["min_dihedral_deg"] > 0.4 * quality_summary(X, tets)["min_dihedral_deg"]


def test_refined_model_is_the_same_face_and_simulates_alike(small_model):
    m = small_model
    r = refine(m)
    assert len(r.tets) == 8 * len(m.tets) and r.meta["refined"] == 1
    # the render surface sits where it did at rest, in the child tets
    assert np.abs(r.embedded_surface(r.rest_positions) - m.embedded_surface(m.rest_positions)).max() < 1e-12
    inside = m.embed_weights.min(1) > -1e-9        # (points outside the flesh extrapolate)
    assert inside.sum() > 1000 and np.all(r.embed_weights[inside] > -1e-9)
    # the rest state is the equilibrium; fixed midpoints follow the jaw
    s0, s1 = Simulator(m), Simulator(r)
    assert s1.solve().iterations == 0
    jaw = [0.15, 0, 0, 0, 0, 0]
    x1 = r.skinned_volume(jaw)[r.fixed_jaw]
    assert np.abs(s1.constrained_positions(jaw)[r.fixed_jaw] - x1).max() < 1e-12
    assert len(r.fixed_jaw) > len(m.fixed_jaw) and len(r.fixed_cranium) > len(m.fixed_cranium)
    # a smile: the mouth corner moves alike on both meshes (mesh convergence, within 25 %)
    acts = {n: 0.6 for n in s0.muscle_names if n.startswith("zygomaticus_major")}
    corner = m.landmarks["mouth_corner_L"]
    d0 = s0.surface(s0.solve(acts))[corner] - m.neutral[corner]
    d1 = s1.surface(s1.solve(acts))[corner] - r.neutral[corner]
    assert np.linalg.norm(d0) > 1e-3
    assert np.linalg.norm(d1 - d0) < 0.25 * np.linalg.norm(d0), (d0, d1)


def test_refined_tracks_are_solved_again_on_the_finer_mesh(small_expressive_model):
    """Eq. 10-11's Poisson displacements are solved on the refined mesh: at the old vertices
    they stay near the coarse solution (7 % in norm on the small head), not equal to it."""
    m = small_expressive_model
    r = refine(m)
    a, b = m.track_displacements, r.track_displacements
    assert b.shape == (len(m.blendshape_names), len(r.rest_positions), 3) and np.all(np.isfinite(b))
    rel = np.linalg.norm(b[:, :a.shape[1]] - a) / np.linalg.norm(a)
    assert 1e-4 < rel < 0.15, rel
