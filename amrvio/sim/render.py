"""Per-plane exact rendering of a :class:`~amrvio.sim.scene.Scene` with z-buffer occlusion.

For each quad facing the camera and inside the view frustum, the renderer

1. splits the quad (in its own parameter plane) into pieces whose depth varies by at most a factor
   ``split_ratio``, so one mip level fits each piece (pre-filtered texture, no aliasing);
2. clips each piece against the near plane and projects it with the ideal pinhole K;
3. rasterises it exactly: a pixel belongs to the piece when its centre lies inside the projected
   polygon (per-row spans from the edge functions);
4. z-tests with the plane's inverse depth, which is an exact affine function of the pixel for a
   plane: ``1/z = n . K^-1 [u, v, 1] / d`` for the plane ``n . X = d`` in camera coordinates;
5. samples the texture through the exact texture -> image homography ``H = K [a/tpm, b/tpm, o]``
   (cv2.warpPerspective, bilinear, wrap-around tiling) and writes ``radiance * albedo``.

Distorted cameras (radtan, equidistant) are rendered on a larger ideal pinhole canvas with the same
focal lengths, then resampled once per image with cv2.remap through the camera's exact inverse
distortion (``camera.undistort_points``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.sim.scene import Scene
from amrvio.sim.textures import MipTexture
from amrvio.types.camera import CameraModel, PinholeCamera
from amrvio.types.lie import SE3

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

_PARAM_EPS = 1e-6  # overlap of sibling pieces (fraction of the quad) so that no pixel is missed


@dataclass(frozen=True, slots=True)
class RenderStats:
    """Counters of the last render (for benchmarks)."""

    quads_visible: int
    pieces_drawn: int
    pixels_tested: int


class SceneRenderer:
    """Renders scene radiance and z-depth seen by ``camera`` from a pose ``T_world_cam``.

    ``near_m``: near clipping distance. ``split_ratio``: max ratio of far to near depth in one piece.
    ``mip_bias``: added to the log2 texel footprint when picking the mip level (> 0 blurs more).
    ``supersample``: rasterise on an s-times finer canvas and box-average down (pixel-area
    integration: anti-aliased silhouettes, about s^2 times the pixel work). Depth stays exact inside
    planes; at silhouettes it is the nearest of the sub-samples around the pixel centre.
    """

    def __init__(
        self,
        scene: Scene,
        camera: CameraModel,
        near_m: float = 0.05,
        split_ratio: float = 2.0,
        mip_bias: float = 0.0,
        supersample: int = 1,
    ) -> None:
        import cv2

        if near_m <= 0 or split_ratio <= 1.0:
            raise ShapeError("near_m must be > 0 and split_ratio > 1")
        if not 1 <= int(supersample) <= 4:
            raise ShapeError(f"supersample must be 1..4, got {supersample}")
        self.supersample = int(supersample)
        self.scene = scene
        self.camera = camera
        self.near_m = float(near_m)
        self.split_ratio = float(split_ratio)
        self.mip_bias = float(mip_bias)
        self._mips = [MipTexture.build(t) for t in scene.textures]
        q = scene.quads
        self._corners = np.stack([qd.corners_world for qd in q])  # (Q, 4, 3)
        a = self._corners[:, 1] - self._corners[:, 0]
        b = self._corners[:, 3] - self._corners[:, 0]
        self._len_a = np.linalg.norm(a, axis=1)
        self._len_b = np.linalg.norm(b, axis=1)
        self._a_hat = a / self._len_a[:, None]
        self._b_hat = b / self._len_b[:, None]
        n = np.cross(a, b)
        self._normals = n / np.linalg.norm(n, axis=1)[:, None]
        self._two_sided = np.array([qd.two_sided for qd in q])
        self._tpm = np.array([qd.texels_per_m for qd in q])
        self._radiance = np.array([qd.radiance for qd in q])
        self._offsets = np.array([qd.offset_texels for qd in q], dtype=np.float64)
        self._tex_id = np.array([qd.texture_id for qd in q])
        self.last_stats = RenderStats(0, 0, 0)

        self._remap: tuple[NDArray[np.int16], NDArray[np.uint16]] | None = None
        self._remap_near: tuple[F32, F32] | None = None
        if camera.distortion_model == "none":
            self._canvas: CameraModel = camera.pinhole()
        else:
            self._canvas = self._distorted_canvas(camera)
            us, vs = np.meshgrid(np.arange(camera.width, dtype=np.float64),
                                 np.arange(camera.height, dtype=np.float64))
            ideal = camera.undistort_points(np.stack([us.ravel(), vs.ravel()], axis=1))
            ideal[:, 0] += self._canvas.cx - camera.cx
            ideal[:, 1] += self._canvas.cy - camera.cy
            ideal[~np.isfinite(ideal)] = -10.0
            mx = ideal[:, 0].reshape(camera.height, camera.width).astype(np.float32)
            my = ideal[:, 1].reshape(camera.height, camera.width).astype(np.float32)
            m1, m2 = cv2.convertMaps(mx, my, cv2.CV_16SC2)
            self._remap = (m1, m2)
            self._remap_near = (mx, my)
        self._base = self._canvas
        ss = self.supersample
        if ss > 1:  # pixel centres: u_fine = ss (u + 0.5) - 0.5
            self._canvas = self._base.scaled(ss)

        self._zbuf = np.zeros((self._canvas.height, self._canvas.width), np.float32)
        self._img = np.zeros((self._canvas.height, self._canvas.width), np.float32)
        self._cols = np.arange(self._canvas.width, dtype=np.float32)
        self._rows = np.arange(self._canvas.height, dtype=np.float64)

    # ----- public API -------------------------------------------------------------------------------

    def irradiance(self, T_world_cam: SE3) -> F32:
        """(H, W) float32 linear scene radiance seen by the camera (>= 0; 0 where nothing)."""
        return self.render(T_world_cam)[0]

    def depth(self, T_world_cam: SE3) -> F32:
        """(H, W) float32 z-depth in metres along the optical axis; inf where nothing is seen.

        Pinhole cameras: exact at every pixel centre. Distorted cameras: the depth of the nearest
        sample of the ideal canvas (within half a pixel)."""
        img, depth = self._rasterise(T_world_cam, texture=False)
        return self._finish_depth(depth)

    def render(self, T_world_cam: SE3) -> tuple[F32, F32]:
        """Both ``(irradiance, depth)`` from one rasterisation."""
        img, inv_depth = self._rasterise(T_world_cam, texture=True)
        return self.finish_irradiance(img), self._finish_depth(inv_depth)

    def canvas_irradiance(self, T_world_cam: SE3) -> tuple[F32, F32]:
        """(irradiance, inverse depth) on the ideal canvas, before resampling through the
        distortion. Averaging canvases then calling :meth:`finish_irradiance` once is the same as
        averaging final images (the remap is linear)."""
        return self._rasterise(T_world_cam, texture=True)

    def finish_irradiance(self, canvas: F32) -> F32:
        """Canvas radiance -> camera image (identity for a pinhole camera)."""
        import cv2

        if self.supersample > 1:
            canvas = cv2.resize(canvas, (self._base.width, self._base.height),
                                interpolation=cv2.INTER_AREA)
        if self._remap is None:
            return canvas
        out: F32 = cv2.remap(canvas, self._remap[0], self._remap[1], cv2.INTER_LINEAR,
                             borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        return out

    def finish_depth(self, inv_depth_canvas: F32) -> F32:
        """Canvas inverse depth -> camera z-depth (inf where nothing)."""
        return self._finish_depth(inv_depth_canvas)

    # ----- internals --------------------------------------------------------------------------------

    @staticmethod
    def _distorted_canvas(camera: CameraModel) -> PinholeCamera:
        """Smallest ideal pinhole canvas (same fx, fy) covering the distorted image's field of view."""
        w, h = camera.width, camera.height
        border = np.concatenate([
            np.stack([np.arange(w), np.zeros(w)], 1), np.stack([np.arange(w), np.full(w, h - 1)], 1),
            np.stack([np.zeros(h), np.arange(h)], 1), np.stack([np.full(h, w - 1), np.arange(h)], 1),
        ]).astype(np.float64)
        ideal = camera.undistort_points(border)
        ideal = ideal[np.all(np.isfinite(ideal), axis=1)]
        if ideal.shape[0] == 0:
            raise ShapeError("camera distortion is not invertible on the image border")
        lo = np.minimum(ideal.min(axis=0), 0.0) - 2.0
        hi = np.maximum(ideal.max(axis=0), [w - 1, h - 1]) + 2.0
        lo = np.maximum(lo, [-1.5 * w, -1.5 * h])  # cap extreme fields of view
        hi = np.minimum(hi, [2.5 * w, 2.5 * h])
        u0, v0 = math.floor(lo[0]), math.floor(lo[1])
        cw, ch = math.ceil(hi[0]) - u0 + 1, math.ceil(hi[1]) - v0 + 1
        return PinholeCamera(int(cw), int(ch), camera.fx, camera.fy, camera.cx - u0, camera.cy - v0)

    def _finish_depth(self, inv_depth: F32) -> F32:
        import cv2

        ss = self.supersample
        if ss > 1:
            if ss % 2:  # a sub-sample sits exactly on each pixel centre
                inv_depth = np.ascontiguousarray(inv_depth[ss // 2 :: ss, ss // 2 :: ss])
            else:  # the 4 sub-samples around the centre: their mean is exact on one plane
                h0 = ss // 2 - 1
                quad = np.stack([inv_depth[h0 + i :: ss, h0 + j :: ss] for i in (0, 1)
                                 for j in (0, 1)])
                hi_v = quad.max(axis=0)
                # One plane <=> affine on the 2x2 block <=> f00 + f11 == f01 + f10.
                same = np.abs(quad[0] + quad[3] - quad[1] - quad[2]) <= 1e-5 * hi_v
                same &= quad.min(axis=0) > 0
                inv_depth = np.where(same, quad.mean(axis=0), hi_v).astype(np.float32)

        if self._remap_near is not None:
            inv_depth = cv2.remap(inv_depth, self._remap_near[0], self._remap_near[1],
                                  cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
        with np.errstate(divide="ignore"):
            depth = np.where(inv_depth > 0, 1.0 / inv_depth, np.inf).astype(np.float32)
        return depth

    def _rasterise(self, T_world_cam: SE3, texture: bool) -> tuple[F32, F32]:
        """Returns (radiance canvas, inverse-depth canvas), both new arrays."""
        cv = self._canvas
        T_cam_world = T_world_cam.inverse()
        R, t = T_cam_world.R, T_cam_world.t
        Cc = self._corners @ R.T + t  # (Q, 4, 3) corners in the camera frame
        cam_pos = T_world_cam.t
        # Back faces of closed solids are invisible.
        facing = np.einsum("qj,qj->q", self._normals, cam_pos[None, :] - self._corners[:, 0])
        keep = self._two_sided | (facing > 1e-9)
        keep &= ~_all_outside(Cc, cv, self.near_m)
        idx = np.flatnonzero(keep)
        self._zbuf.fill(0.0)
        self._img.fill(0.0)
        if idx.size == 0:
            self.last_stats = RenderStats(0, 0, 0)
            return self._img.copy(), self._zbuf.copy()
        leaves_q, leaves_prm, leaves_zmin = self._split_all(Cc, idx)
        order = np.argsort(leaves_zmin, kind="stable")  # front to back: occluded pieces fail early
        leaves_q, leaves_prm = leaves_q[order], leaves_prm[order]

        # Grow internal edges by a hair so that sibling pieces overlap (no cracks).
        prm = leaves_prm.copy()
        prm[:, 0] = np.where(prm[:, 0] > 0, prm[:, 0] - _PARAM_EPS, prm[:, 0])
        prm[:, 2] = np.where(prm[:, 2] > 0, prm[:, 2] - _PARAM_EPS, prm[:, 2])
        prm[:, 1] = np.where(prm[:, 1] < 1, prm[:, 1] + _PARAM_EPS, prm[:, 1])
        prm[:, 3] = np.where(prm[:, 3] < 1, prm[:, 3] + _PARAM_EPS, prm[:, 3])
        P = _piece_corners(Cc, leaves_q, prm)  # (L, 4, 3)
        with np.errstate(divide="ignore", invalid="ignore"):
            U = cv.fx * P[..., 0] / P[..., 2] + cv.cx
            V = cv.fy * P[..., 1] / P[..., 2] + cv.cy
        needs_clip = np.any(P[..., 2] < self.near_m, axis=1)

        # Per-quad plane (inverse depth) and texture homographies, camera frame.
        qs = np.unique(leaves_q)
        n_cam = self._normals[qs] @ R.T
        c0 = Cc[qs, 0]
        d = np.einsum("qj,qj->q", n_cam, c0)
        ok_plane = np.abs(d) > 1e-12
        d_safe = np.where(ok_plane, d, 1.0)
        inv_coef = np.stack([
            n_cam[:, 0] / (cv.fx * d_safe),
            n_cam[:, 1] / (cv.fy * d_safe),
            (n_cam[:, 2] - n_cam[:, 0] * cv.cx / cv.fx - n_cam[:, 1] * cv.cy / cv.fy) / d_safe,
        ], axis=1)
        K = np.array([[cv.fx, 0.0, cv.cx], [0.0, cv.fy, cv.cy], [0.0, 0.0, 1.0]])
        ah = self._a_hat[qs] @ R.T
        bh = self._b_hat[qs] @ R.T
        tpm = self._tpm[qs]
        off = self._offsets[qs]
        # X_cam(s, t) = c0 + (s - off_s)/tpm a_hat + (t - off_t)/tpm b_hat  (scene.Quad texture map)
        o = c0 - (off[:, 0] / tpm)[:, None] * ah - (off[:, 1] / tpm)[:, None] * bh
        H_img_tex = K[None] @ np.stack([ah / tpm[:, None], bh / tpm[:, None], o], axis=2)
        with np.errstate(all="ignore"):
            H_tex_img = np.linalg.inv(H_img_tex)
        slot = np.full(len(self._corners), -1)
        slot[qs] = np.arange(qs.size)

        # Texel footprint at each piece centre -> mip level (isotropic, area preserving).
        centre = 0.25 * P.sum(axis=1)
        zc = np.maximum(centre[:, 2], self.near_m)
        ray = centre / np.maximum(np.linalg.norm(centre, axis=1), 1e-12)[:, None]
        cos_t = np.maximum(np.abs(np.einsum("lj,lj->l", ray, n_cam[slot[leaves_q]])), 0.05)
        texels_per_px = zc * self._tpm[leaves_q] / (cv.fx * np.sqrt(cos_t))
        level = np.round(np.log2(np.maximum(texels_per_px, 1e-9)) + self.mip_bias).astype(int)
        # Texture coordinates of the piece centres, to shift by whole periods (16-bit remap).
        cu = cv.fx * centre[:, 0] / zc + cv.cx
        cvv = cv.fy * centre[:, 1] / zc + cv.cy
        Hl = H_tex_img[slot[leaves_q]]
        den = Hl[:, 2, 0] * cu + Hl[:, 2, 1] * cvv + Hl[:, 2, 2]
        s_c = (Hl[:, 0, 0] * cu + Hl[:, 0, 1] * cvv + Hl[:, 0, 2]) / den
        t_c = (Hl[:, 1, 0] * cu + Hl[:, 1, 1] * cvv + Hl[:, 1, 2]) / den

        zmin_l = P[..., 2].min(axis=1)
        max_inv_z = np.where(zmin_l > self.near_m, 1.0 / np.maximum(zmin_l, self.near_m), np.inf)
        # Bounding boxes and edge lines of the unclipped pieces, vectorised (see _row_spans).
        with np.errstate(invalid="ignore"):
            bb = np.stack([np.ceil(U.min(axis=1)), np.floor(U.max(axis=1)),
                           np.ceil(V.min(axis=1)), np.floor(V.max(axis=1))], axis=1)
        bb[:, 0] = np.maximum(bb[:, 0], 0)
        bb[:, 1] = np.minimum(bb[:, 1], cv.width - 1)
        bb[:, 2] = np.maximum(bb[:, 2], 0)
        bb[:, 3] = np.minimum(bb[:, 3], cv.height - 1)
        on_screen = needs_clip | ((bb[:, 1] >= bb[:, 0]) & (bb[:, 3] >= bb[:, 2]))
        lines = _edge_lines(U, V)
        bbi = np.where(np.isfinite(bb), bb, 0).astype(np.int64)
        n_drawn = 0
        n_px = 0
        for i in np.flatnonzero(on_screen & ok_plane[slot[leaves_q]]).tolist():
            q = int(leaves_q[i])
            k = int(slot[q])
            if needs_clip[i]:
                poly = _clip_near(P[i], self.near_m)
                if poly.shape[0] < 3:
                    continue
                u = cv.fx * poly[:, 0] / poly[:, 2] + cv.cx
                v = cv.fy * poly[:, 1] / poly[:, 2] + cv.cy
                u0 = max(0, math.ceil(float(u.min())))
                u1 = min(cv.width - 1, math.floor(float(u.max())))
                v0 = max(0, math.ceil(float(v.min())))
                v1 = min(cv.height - 1, math.floor(float(v.max())))
                if u1 < u0 or v1 < v0:
                    continue
                lo, hi = _row_spans(u, v, self._rows[v0 : v1 + 1])
            else:
                u0, u1, v0, v1 = bbi[i].tolist()
                rows = self._rows[v0 : v1 + 1]
                lo = (lines[i, 0, :, :1] * rows + lines[i, 0, :, 1:]).max(axis=0)
                hi = (lines[i, 1, :, :1] * rows + lines[i, 1, :, 1:]).min(axis=0)
            drawn, px = self._draw_piece(q, u0, u1, v0, v1, lo, hi, inv_coef[k], Hl[i],
                                         int(level[i]), float(s_c[i]), float(t_c[i]),
                                         float(max_inv_z[i]), texture)
            n_drawn += drawn
            n_px += px
        self.last_stats = RenderStats(int(idx.size), n_drawn, n_px)
        return self._img.copy(), self._zbuf.copy()

    def _split_all(self, Cc: F64, idx: NDArray[np.intp]) -> tuple[NDArray[np.intp], F64, F64]:
        """Split the quads ``idx`` (breadth first, vectorised) into pieces whose depth varies by at
        most ``split_ratio`` (or that are near enough for the finest mip level). Returns the quad
        index (L,), parameter rectangle [a0, a1, b0, b1] (L, 4) and nearest depth (L,) of each."""
        z_fine = self._canvas.fx / self._tpm
        q = idx.copy()
        prm = np.tile(np.array([0.0, 1.0, 0.0, 1.0]), (q.size, 1))
        out_q: list[NDArray[np.intp]] = []
        out_prm: list[F64] = []
        out_z: list[F64] = []
        for depth in range(17):
            if q.size == 0:
                break
            P = _piece_corners(Cc, q, prm)
            visible = ~_all_outside(P, self._canvas, self.near_m) if depth else np.ones(q.size, bool)
            z = P[..., 2]
            zmin, zmax = z.min(axis=1), z.max(axis=1)
            leaf = (zmax <= z_fine[q]) | ((zmin > self.near_m) & (zmax <= self.split_ratio * zmin))
            if depth == 16:
                leaf[:] = True
            done = leaf & visible
            out_q.append(q[done])
            out_prm.append(prm[done])
            out_z.append(zmin[done])
            split = ~leaf & visible
            q, prm = q[split], prm[split]
            A = Cc[q, 1] - Cc[q, 0]
            B = Cc[q, 3] - Cc[q, 0]
            along_a = np.abs(A[:, 2]) * (prm[:, 1] - prm[:, 0]) >= np.abs(B[:, 2]) * (
                prm[:, 3] - prm[:, 2])
            first = prm.copy()
            second = prm.copy()
            am = 0.5 * (prm[:, 0] + prm[:, 1])
            bm = 0.5 * (prm[:, 2] + prm[:, 3])
            first[:, 1] = np.where(along_a, am, prm[:, 1])
            second[:, 0] = np.where(along_a, am, prm[:, 0])
            first[:, 3] = np.where(along_a, prm[:, 3], bm)
            second[:, 2] = np.where(along_a, prm[:, 2], bm)
            q = np.concatenate([q, q])
            prm = np.concatenate([first, second])
        return np.concatenate(out_q), np.concatenate(out_prm), np.concatenate(out_z)

    def _draw_piece(self, q: int, u0: int, u1: int, v0: int, v1: int, lo: F64, hi: F64,
                    inv_coef: F64, H_tex_img: F64, level: int, s_c: float, t_c: float,
                    max_inv_z: float, texture: bool) -> tuple[int, int]:
        """Rasterise one convex piece: bounding box [u0, u1] x [v0, v1], inside span [lo, hi] of
        each row. Returns (drawn, tested pixels)."""
        import cv2

        zroi = self._zbuf[v0 : v1 + 1, u0 : u1 + 1]
        if max_inv_z < float(zroi.min()):
            return 0, 0  # hidden behind what is already drawn
        rows = self._rows[v0 : v1 + 1]
        cols = self._cols[u0 : u1 + 1]
        inside = (cols[None, :] >= lo[:, None]) & (cols[None, :] <= hi[:, None])
        # Inverse depth of the plane, exact and affine in the pixel (see the module docstring).
        inv_z = (np.float32(inv_coef[0]) * cols[None, :]
                 + (inv_coef[1] * rows + inv_coef[2]).astype(np.float32)[:, None])
        mask = (inv_z > zroi) & inside
        mask_u8 = mask.view(np.uint8)
        n_px = int(mask.size)
        if cv2.countNonZero(mask_u8) == 0:
            return 0, n_px
        cv2.copyTo(inv_z, mask_u8, zroi)
        if not texture:
            return 1, n_px
        iroi = self._img[v0 : v1 + 1, u0 : u1 + 1]
        mip = self._mips[int(self._tex_id[q])]
        rad = np.float32(self._radiance[q])
        if mip.is_constant:
            val = np.full(inv_z.shape, rad * mip.levels[0][0, 0], np.float32)
            cv2.copyTo(val, mask_u8, iroi)
            return 1, n_px
        level = min(max(level, 0), len(mip.levels) - 1)
        size0 = mip.size
        # Keep the coordinates small (the remap works in 16-bit fixed point): shift by whole periods.
        sh_s = math.floor(s_c / size0) * size0 if math.isfinite(s_c) else 0.0
        sh_t = math.floor(t_c / size0) * size0 if math.isfinite(t_c) else 0.0
        sc = 0.5**level
        M = np.array([[sc, 0.0, -sc * sh_s], [0.0, sc, -sc * sh_t], [0.0, 0.0, 1.0]]) @ H_tex_img
        M[:, 2] += M[:, 0] * u0 + M[:, 1] * v0  # ROI offset
        warped = cv2.warpPerspective(mip.levels[level], M, (u1 - u0 + 1, v1 - v0 + 1),
                                     flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                     borderMode=cv2.BORDER_WRAP)
        if rad != 1.0:
            warped *= rad
        cv2.copyTo(warped, mask_u8, iroi)
        return 1, n_px


def _piece_corners(Cc: F64, q: NDArray[np.intp], prm: F64) -> F64:
    """(L, 4, 3) camera-frame corners of the pieces [a0, a1, b0, b1] of quads q."""
    C0 = Cc[q, 0]
    A = Cc[q, 1] - C0
    B = Cc[q, 3] - C0
    a = prm[:, [0, 1, 1, 0]]
    b = prm[:, [2, 2, 3, 3]]
    return np.asarray(C0[:, None, :] + a[..., None] * A[:, None, :] + b[..., None] * B[:, None, :])


def _all_outside(Cc: F64, cv: CameraModel, near: float) -> NDArray[np.bool_]:
    """(Q,) True where all 4 corners of a (Q, 4, 3) camera-frame quad are outside one frustum plane.

    Side planes pass through the optical centre: u >= -0.5 <=> fx x + (cx + 0.5) z >= 0, etc."""
    x, y, z = Cc[..., 0], Cc[..., 1], Cc[..., 2]
    out = np.all(z < near, axis=1)
    out |= np.all(cv.fx * x + (cv.cx + 0.5) * z < 0, axis=1)
    out |= np.all((cv.width - 0.5 - cv.cx) * z - cv.fx * x < 0, axis=1)
    out |= np.all(cv.fy * y + (cv.cy + 0.5) * z < 0, axis=1)
    out |= np.all((cv.height - 0.5 - cv.cy) * z - cv.fy * y < 0, axis=1)
    return out


def _clip_near(poly: F64, near: float) -> F64:
    """Sutherland-Hodgman clip of a convex (K, 3) polygon to z >= near."""
    z = poly[:, 2]
    if np.all(z >= near):
        return poly
    out: list[F64] = []
    k = poly.shape[0]
    for i in range(k):
        p, qv = poly[i], poly[(i + 1) % k]
        pin, qin = p[2] >= near, qv[2] >= near
        if pin:
            out.append(p)
        if pin != qin:
            s = (near - p[2]) / (qv[2] - p[2])
            out.append(p + s * (qv - p))
    return np.array(out) if out else np.zeros((0, 3))


def _edge_lines(U: F64, V: F64) -> F64:
    """(L, 2, 4, 2) per piece: 4 lines ``u = slope * row + icpt`` bounding the inside from the left
    (index 0, take the max) and from the right (index 1, take the min) for quads with projected
    vertices (L, 4). Unused slots are (0, -inf) / (0, +inf). Horizontal edges need no line: the
    bounding box rows already stop at them."""
    U2 = np.roll(U, -1, axis=1)
    V2 = np.roll(V, -1, axis=1)
    area = np.sum(U * V2 - U2 * V, axis=1)
    flip = area < 0  # orient so that the interior is e >= 0 (see _row_spans)
    A = np.where(flip[:, None], -(V - V2), V - V2)
    B = np.where(flip[:, None], -(U2 - U), U2 - U)
    C = np.where(flip[:, None], -(-(U2 - U) * V + (V2 - V) * U), -(U2 - U) * V + (V2 - V) * U)
    out = np.zeros((U.shape[0], 2, 4, 2))
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = -B / A
        icpt = -C / A
    pos = A > 0
    neg = A < 0
    out[:, 0, :, 0] = np.where(pos, slope, 0.0)
    out[:, 0, :, 1] = np.where(pos, icpt, -np.inf)
    out[:, 1, :, 0] = np.where(neg, slope, 0.0)
    out[:, 1, :, 1] = np.where(neg, icpt, np.inf)
    return out


def _row_spans(u: F64, v: F64, rows: F64) -> tuple[F64, F64]:
    """For a convex polygon (K vertices u, v), the inside interval [lo, hi] of u on each row.

    Pixel centre (c, r) is inside when every edge function e = A c + B r + C >= 0 (interior on the
    positive side after orienting the polygon)."""
    uu: list[float] = u.tolist()
    vv: list[float] = v.tolist()
    k = len(uu)
    area = sum(uu[i] * vv[(i + 1) % k] - uu[(i + 1) % k] * vv[i] for i in range(k))
    if area < 0:  # orient so that the interior is e >= 0
        uu.reverse()
        vv.reverse()
    lo_lines: list[tuple[float, float]] = []
    hi_lines: list[tuple[float, float]] = []
    lo_extra = np.zeros(rows.shape, bool)
    for i in range(k):
        ua, va, ub, vb = uu[i], vv[i], uu[(i + 1) % k], vv[(i + 1) % k]
        A, B = va - vb, ub - ua
        C = -B * va + (vb - va) * ua
        if A > 0:
            lo_lines.append((-B / A, -C / A))  # u >= (-B r - C) / A
        elif A < 0:
            hi_lines.append((-B / A, -C / A))
        else:
            lo_extra |= B * rows + C < 0  # horizontal edge: whole row out
    if lo_lines:
        m = np.array(lo_lines)
        lo = (m[:, :1] * rows[None, :] + m[:, 1:]).max(axis=0)
    else:
        lo = np.full(rows.shape, -np.inf)
    if hi_lines:
        m = np.array(hi_lines)
        hi = (m[:, :1] * rows[None, :] + m[:, 1:]).min(axis=0)
    else:
        hi = np.full(rows.shape, np.inf)
    if lo_extra.any():
        lo[lo_extra] = np.inf
    return lo, hi
