"""The image Jacobian with visibility held fixed, as OpenDR differentiates (paper 000's renderer).

One ray cast per linearisation finds, for ``samples`` x ``samples`` stratified rays per pixel,
the skin triangle each ray hits first and its barycentrics b (a ray that meets the background
or an inner part first carries no derivative, as in the renderer's interior term). A pixel's
radiance is then I = 1/S sum_s sum_j b_sj c_j, the barycentric mean of the vertex radiances
c_j = a_j * E(n_j)/pi (``shading``), and its derivative along a motion dx of the posed
vertices has two parts:

- shading: sum_s sum_j b_sj dc_j, with dc_j the SH radiance's analytic derivative through the
  area-weighted vertex normal n_j (which moves with the vertex's one-ring);
- the hit point sliding on its triangle under a fixed ray: with E = [x1 - x0, x2 - x0, -d] and
  p the hit, d(b1, b2) = -(rows 0-1 of E^-1) dp for dp = sum_j b_j dx_j, so
  dI = M_s dp with M_s = -((c1 - c0) r0^T + (c2 - c0) r1^T) (3 channels x 3 coordinates).

dp varies smoothly over a pixel, M_s per triangle; the pixel's term is taken as mean_s(M_s) times
the pixel's mean dp (their covariance within one pixel is second order). So for a fit's
controls z, with dx/dz (V, 3, n) from the rig or the simulation's tangents,

    dI/dz = Wb dC/dz + Mbar * (Wb dx/dz)

where Wb (pixels x V) is the sample-averaged barycentric matrix: every product goes through
it once, and no render pass is made per control. Silhouette and occlusion edges are not in it
(their derivative is Dr.Jit's projective sampling; the fit's gradient keeps it); ``band`` marks
the pixels within ``BAND`` px of such an edge.

Works on Mitsuba's ``llvm_ad_rgb`` and ``cuda_ad_rgb`` alike: the only Mitsuba call is the
scene's ray intersection; the rest is numpy on the arrays it returns.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..mesh.triangles import unique_edges
from .shading import BAND_WEIGHTS, _Y, shading_basis

BAND = 2                 # px: the band around silhouettes and occlusion edges that ``band`` marks
EDGE_STRETCH = 4.0       # an occlusion edge or fold: neighbouring hits further apart than this many pixel footprints
CHUNK = 16               # columns of dI/dz made at once (memory: pixels x 3 x CHUNK floats)


def radiance_normal_gradient(normals, gamma, albedo):
    """d(vertex radiance)/d(unit normal) (V, 3 channels, 3 coordinates) for unit normals (V,3),
    SH light gamma (9,3) and albedo (V,3): the derivative of a * (B(n) @ gamma) in n."""
    x, y, z = np.asarray(normals, float).T
    w = _Y * BAND_WEIGHTS / np.pi
    g = np.asarray(gamma, float).reshape(9, 3)
    one = np.ones_like(x)
    # rows: d/dx, d/dy, d/dz of each basis function (V, 9)
    dx = np.stack([0 * x, 0 * x, 0 * x, one, y, 0 * x, 0 * x, z, 2 * x], 1) * w
    dy = np.stack([0 * x, one, 0 * x, 0 * x, x, z, 0 * x, 0 * x, -2 * y], 1) * w
    dz = np.stack([0 * x, 0 * x, one, 0 * x, 0 * x, y, 6 * z, x, 0 * x], 1) * w
    grad = np.stack([dx @ g, dy @ g, dz @ g], 2)                  # (V, channel, coordinate)
    return np.asarray(albedo, float).reshape(-1, 3)[:, :, None] * grad


class Linearisation:
    """The image model linearised at one posed surface: ``apply(Jx)`` gives dI/dz.

    shape (h, w): the window; rows (P,): the flat pixel ids with a skin hit; W: CSR (P, V)
    sample-averaged barycentrics of their skin hits; blocks (nnz(W), 3, 3): at each of W's
    nonzeros (pixel, vertex j) the hit points' slide term 1/S sum_s b_sj M_s; band: (h, w)
    bool, the pixels within BAND px of a silhouette or occlusion edge (their slide term is
    zero: ``edge`` replaces it); face: (h, w) bool, pixels all of whose rays hit the skin;
    edge: None, or (band pixel ids (E,), W_e CSR (E, V) the barycentrics of the skin point
    each shows or lies beside, G_e (E, 3, 3) = -(image gradient (3, 2) x that point's
    projection Jacobian (2, 3))): the band's advection term -grad I . du."""

    def __init__(self, shape, rows, W, blocks, band, face, radiance, edge=None):
        self.shape, self.rows, self.W, self.band, self.face, self.edge = shape, rows, W, band, face, edge
        # the slide term as nine matrices on W's pattern: entry (c, d) of every block
        self.slide = [[sp.csr_matrix((np.ascontiguousarray(blocks[:, c, d]), W.indices, W.indptr), shape=W.shape)
                       for d in range(3)] for c in range(3)]
        self._radiance = radiance          # (normals, |m|, d radiance / d n, x, faces, incidence)

    def vertex_radiance_derivative(self, Jx):
        """dC/dz (V, 3 channels, n) of the vertex radiances along dx/dz = Jx (V, 3, n):
        through the area-weighted normals m_j = sum over the one-ring of (x1-x0) x (x2-x0)."""
        n, norm, dcdn, x, faces, inc = self._radiance
        a, b, c = faces.T
        e1, e2 = (x[b] - x[a])[:, :, None], (x[c] - x[a])[:, :, None]
        de1, de2 = Jx[b] - Jx[a], Jx[c] - Jx[a]
        dfn = np.cross(de1, e2, axis=1) + np.cross(e1, de2, axis=1)                 # (F, 3, n)
        dm = (inc @ dfn.reshape(len(faces), -1)).reshape(len(x), 3, -1)
        dn = (dm - n[:, :, None] * np.einsum("vi,vik->vk", n, dm)[:, None, :]) / norm[:, None, None]
        return np.einsum("vcd,vdk->vck", dcdn, dn)

    def apply(self, Jx):
        """dI/dz (h*w, 3, n) float32 for dx/dz = Jx (V, 3, n) m per unit of each z."""
        Jx = np.asarray(Jx, np.float64)
        V, _, n = Jx.shape
        dC = self.vertex_radiance_derivative(Jx).reshape(V, -1).astype(np.float32)
        hits = (self.W @ dC).reshape(-1, 3, n)
        motion = [np.ascontiguousarray(Jx[:, d, :], np.float32) for d in range(3)]
        for c in range(3):
            for d in range(3):
                hits[:, c, :] += self.slide[c][d] @ motion[d]
        out = np.zeros((self.shape[0] * self.shape[1], 3, n), np.float32)
        out[self.rows] = hits
        if self.edge is not None:
            pixels, We, Ge = self.edge
            dp = np.stack([We @ motion[d] for d in range(3)], 1)                   # (E, 3, n)
            out[pixels] += np.einsum("ecd,edk->eck", Ge, dp)
        return out

    def columns(self, Jz, each):
        """Call each(k0, block (h, w, 3, m)) for the derivative images of dx/dz = Jz (n, V, 3)
        in blocks of at most CHUNK columns k0..k0+m (memory stays pixels x 3 x CHUNK)."""
        h, w = self.shape
        for k0 in range(0, len(Jz), CHUNK):
            Jx = np.moveaxis(np.asarray(Jz[k0:k0 + CHUNK], np.float64), 0, 2)      # (V, 3, m)
            each(k0, self.apply(Jx).reshape(h, w, 3, -1))


def _pixel_sums(pix, tri, bary, Ms, V, k2):
    """Each hit pixel's sums over its rays: (pixel ids (P,), W CSR (P, V) float32 of the
    barycentric weights bary (hits, 3) (already / k2) at the triangles' vertices tri (hits, 3),
    blocks (nnz(W), 3, 3) float32 of weight x slide term Ms (hits, 3, 3)). One ray per pixel
    (k2 = 1) needs no merging: its row is its triangle's three vertices."""
    if k2 == 1:
        P = len(pix)
        W = sp.csr_matrix((bary.ravel().astype(np.float32), tri.ravel(), np.arange(0, 3 * P + 1, 3)), shape=(P, V))
        return pix, W, (bary[:, :, None, None] * Ms[:, None]).reshape(-1, 3, 3).astype(np.float32)
    rows, prow = np.unique(pix, return_inverse=True)
    key = (prow[:, None] * V + tri).ravel()
    order = np.argsort(key, kind="stable")
    key = key[order]
    start = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    pairs = key[start]
    wts = bary.ravel()[order]
    W = sp.csr_matrix((np.add.reduceat(wts, start).astype(np.float32), pairs % V,
                       np.searchsorted(pairs // V, np.arange(len(rows) + 1))), shape=(len(rows), V))
    Mv = Ms.reshape(-1, 9).astype(np.float32)[order // 3] * wts[:, None].astype(np.float32)
    return rows, W, np.add.reduceat(Mv, start, axis=0).reshape(-1, 3, 3)


class RasterJacobian:
    """Linearises a ``FaceRenderer``'s image at posed surfaces (``linearise``).

    samples: rays per pixel along each axis (stratified, fixed); window (x0, y0, width, height)
    px: the renderer's crop (default the whole image)."""

    def __init__(self, renderer, samples=2, window=None):
        self.renderer, self.k = renderer, int(samples)
        cam = renderer.camera
        self.window = (0, 0, cam.width, cam.height) if window is None else tuple(int(v) for v in window)
        x0, y0, w, h = self.window
        off = (np.arange(self.k) + 0.5) / self.k - 0.5                     # sub-pixel offsets
        py, px = np.divmod(np.arange(w * h), w)
        u = (x0 + px[:, None, None] + off[None, None, :]).repeat(self.k, 1).reshape(-1)
        v = (y0 + py[:, None, None] + off[None, :, None]).repeat(self.k, 2).reshape(-1)
        d = np.stack([u, v, np.ones_like(u)], 1) @ np.linalg.inv(cam.K).T @ cam.R     # world directions
        self.d = d / np.linalg.norm(d, axis=1, keepdims=True)
        self.origin = np.asarray(cam.center, float)
        self._ray = None
        self.footprint = 1.0 / float(cam.K[0, 0])                          # m per px per m of depth
        faces = np.asarray(renderer.faces, np.int64).reshape(-1, 3)
        self.faces = faces
        nf = len(faces)
        self.incidence = sp.csr_matrix((np.ones(3 * nf), (faces.T.ravel(), np.tile(np.arange(nf), 3))),
                                       shape=(renderer.vertex_count, nf))
        # each mesh edge's two faces (the second -1 on the mesh's boundary): the silhouette test
        self.edges, ids = unique_edges(faces)
        order = np.argsort(ids.T.ravel(), kind="stable")
        owner = np.tile(np.arange(nf), 3)[order]
        first = np.searchsorted(ids.T.ravel()[order], np.arange(len(self.edges)))
        count = np.bincount(ids.ravel(), minlength=len(self.edges))
        self.edge_faces = np.stack([owner[first], np.where(count > 1, owner[np.minimum(first + 1, nf * 3 - 1)], -1)], 1)

    def _cast(self, xr, parts_x, rotation, translation):
        """The rays at the posed surface xr (V,3) (the inner parts at parts_x, unposed): (skin
        hit (S,) bool, the hits' ray ids (H,), their triangle ids and barycentrics b1, b2 (H,),
        every ray's distance to its first hit of any shape (S,), inf for a miss)."""
        r, mi, dr = self.renderer, self.renderer.mi, self.renderer.dr
        with dr.suspend_grad():
            if self._ray is None:                # the rays are fixed: made once, as Mitsuba arrays
                o = np.broadcast_to(self.origin, self.d.shape)
                self._ray = mi.Ray3f(mi.Point3f(*(o[:, i].astype(np.float32) for i in range(3))),
                                     mi.Vector3f(*(self.d[:, i].astype(np.float32) for i in range(3))))
            r.place(np.asarray(xr, np.float32), parts_x, rotation, translation)
            pi = r.scene.ray_intersect_preliminary(self._ray, coherent=True)
            valid = np.array(pi.is_valid(), bool)
            hit = valid & np.array(pi.shape == mi.ShapePtr(r.face_shape), bool)
            s = np.flatnonzero(hit)
            prim = np.array(pi.prim_index, np.int64)[s]
            uv = np.array(pi.prim_uv, np.float64)[:, s]
            t = np.array(pi.t, np.float64)
        return hit, s, prim, uv[0], uv[1], np.where(valid, t, np.inf)

    def linearise(self, xr, gamma, albedo, parts_x=None, rotation=None, translation=None, image=None):
        """The ``Linearisation`` at the posed skin xr (V,3) m under light gamma (9,3) and albedo
        (V,3); parts_x: the inner parts' unposed positions with the pose (rotation, translation)
        that places them, as the renderer's ``render`` takes them; image: the render there
        (h, w, 3) linear, whose gradient gives the band's advection term (OpenDR's boundary
        derivative: a silhouette moving by du changes its pixels by -grad I . du); without it
        the band has the interior terms only."""
        from ..mesh.triangles import face_normals
        x = np.asarray(xr, np.float64).reshape(-1, 3)
        V, k2 = len(x), self.k * self.k
        _, _, w, h = self.window
        fn = face_normals(x, self.faces)
        m = self.incidence @ fn
        norm = np.maximum(np.linalg.norm(m, axis=1), 1e-30)
        n = m / norm[:, None]
        g = np.asarray(gamma, float).reshape(9, 3)
        a = np.asarray(albedo, float).reshape(V, 3)
        c = a * (shading_basis(n) @ g)                                      # vertex radiance (V,3)
        hit, s, prim, b1, b2, t = self._cast(x, parts_x, rotation, translation)
        tri = self.faces[prim]
        bary = np.stack([1 - b1 - b2, b1, b2], 1) / k2                      # (hits, 3), / samples
        # the hit point's slide under a fixed ray: rows 0, 1 of E^-1, E = [e1, e2, -d]
        x0 = x[tri[:, 0]]
        e1, e2, nd = x[tri[:, 1]] - x0, x[tri[:, 2]] - x0, -self.d[s]
        det = np.einsum("si,si->s", e1, np.cross(e2, nd))
        det = np.where(np.abs(det) > 1e-30, det, 1e-30)
        r0, r1 = np.cross(e2, nd) / det[:, None], np.cross(nd, e1) / det[:, None]
        ct = c[tri]
        Ms = -(np.einsum("sc,sd->scd", ct[:, 1] - ct[:, 0], r0) + np.einsum("sc,sd->scd", ct[:, 2] - ct[:, 0], r1))
        pix = s // k2
        rows, W, blocks = _pixel_sums(pix, tri, bary, Ms, V, k2)
        count = np.bincount(pix, minlength=w * h)
        face = (count == k2).reshape(h, w)
        band = self._band(hit, t, count, h, w, self._silhouettes(x, fn, t, h, w))
        in_band = band.ravel()[rows]
        blocks[np.repeat(in_band, np.diff(W.indptr))] = 0.0          # the band: advection instead
        edge = None if image is None else self._edge(image, band, rows, W, x, count)
        return Linearisation((h, w), rows, W, blocks, band, face,
                             (n, norm, radiance_normal_gradient(n, g, a), x, self.faces, self.incidence), edge)

    def _edge(self, image, band, rows, W, x, count):
        """The band's advection term (``Linearisation.edge``) from the render image (h, w, 3):
        each band pixel moves with the skin point it shows, or with the nearest skin pixel's
        when it shows none (the background or an inner part beside the skin)."""
        from scipy.ndimage import distance_transform_edt
        h, w = band.shape
        img = np.asarray(image, np.float32).reshape(h, w, -1)[..., :3]
        gu = np.gradient(img, axis=1)                                          # per px, central
        gv = np.gradient(img, axis=0)
        nearest = distance_transform_edt(count.reshape(h, w) == 0, return_distances=False, return_indices=True)
        pixels = np.flatnonzero(band)
        source = nearest[0].ravel()[pixels] * w + nearest[1].ravel()[pixels]
        We = W[np.searchsorted(rows, source)]
        # the projection's Jacobian at the point each band pixel follows (2, 3) per pixel
        cam = self.renderer.camera
        p = We @ x                                                  # barycentric point (E, 3)
        pc = p @ cam.R.T + cam.t
        z = pc[:, 2:3]
        K = cam.K
        du = (np.stack([K[0, 0] / z[:, 0], K[0, 1] / z[:, 0], -(K[0, 0] * pc[:, 0] + K[0, 1] * pc[:, 1]) / z[:, 0] ** 2], 1)) @ cam.R
        dv = (np.stack([np.zeros(len(z)), K[1, 1] / z[:, 0], -K[1, 1] * pc[:, 1] / z[:, 0] ** 2], 1)) @ cam.R
        grad = np.stack([gu.reshape(-1, 3)[pixels], gv.reshape(-1, 3)[pixels]], 2)    # (E, 3, 2)
        Ge = -(grad[:, :, 0, None] * du[:, None, :] + grad[:, :, 1, None] * dv[:, None, :])
        return pixels, We.astype(np.float32), Ge.astype(np.float32)

    def _silhouettes(self, x, fn, t, h, w):
        """(h, w) bool: the pixels crossed by the visible silhouette edges of the posed skin x
        (face normals fn): mesh edges on its boundary or between a face turned towards the
        camera and one turned away, the edges Mitsuba's projective sampling differentiates.
        An edge point is visible where it is no deeper than the first hit at its pixel (1 mm)."""
        f0, f1 = self.edge_faces.T
        facing = np.einsum("fi,fi->f", fn, x[self.faces].mean(1) - self.origin) < 0
        sil = (f1 < 0) | (facing[f0] != facing[np.maximum(f1, 0)])
        a, b = x[self.edges[sil, 0]], x[self.edges[sil, 1]]
        cam = self.renderer.camera
        x0, y0 = self.window[:2]
        depth = t.reshape(-1, self.k * self.k).min(1)          # the nearest hit of any shape
        out = np.zeros(h * w, bool)
        for s in np.linspace(0.0, 1.0, 5):
            p = a + s * (b - a)
            uv, _ = cam.project(p)
            col, row = np.round(uv[:, 0] - x0).astype(np.int64), np.round(uv[:, 1] - y0).astype(np.int64)
            inside = (col >= 0) & (col < w) & (row >= 0) & (row < h)
            pix = row[inside] * w + col[inside]
            dist = np.linalg.norm(p[inside] - self.origin, axis=1)
            out[pix[dist <= depth[pix] + 1e-3]] = True
        return out.reshape(h, w)

    def _band(self, hit, t, count, h, w, silhouettes):
        """Pixels within BAND px of a silhouette or an occlusion edge: a pixel with some but not
        all of its rays on the skin, a skin pixel beside one without, or skin hit points (a
        pixel's rays among themselves, or neighbouring pixels' mean hits) further apart than
        EDGE_STRETCH pixel footprints at their depth: a fold hiding skin behind skin (a lid, a
        lip), or a surface so oblique that it is about to become a silhouette."""
        import cv2
        k2 = self.k * self.k
        skin = (count == k2).reshape(h, w)
        P = np.where(hit[:, None], self.origin + np.where(hit, t, 0.0)[:, None] * self.d, 0.0).reshape(-1, k2, 3)
        mean = P.sum(1) / np.maximum(count, 1)[:, None]
        depth = np.linalg.norm(mean - self.origin, axis=1)
        reach = EDGE_STRETCH * self.footprint * depth                     # m: allowed spacing
        spread = np.where(hit.reshape(-1, k2), np.linalg.norm(P - mean[:, None], axis=2), 0.0).max(1)
        edge = (((count > 0) & (count < k2)) | (spread > 0.5 * reach)).reshape(h, w) | silhouettes
        mean, reach = mean.reshape(h, w, 3), reach.reshape(h, w)
        for a, b in (((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
                     ((slice(None), slice(None, -1)), (slice(None), slice(1, None)))):
            sa, sb = skin[a], skin[b]
            apart = np.linalg.norm(mean[a] - mean[b], axis=-1) > np.minimum(reach[a], reach[b])
            jump = (sa != sb) | (sa & sb & apart)
            edge[a] |= jump
            edge[b] |= jump
        kernel = np.ones((2 * BAND + 1, 2 * BAND + 1), np.uint8)
        return cv2.dilate(edge.astype(np.uint8), kernel) > 0
