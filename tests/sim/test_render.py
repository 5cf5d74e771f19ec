"""Renderer geometry: projected scene points land where drawn, exact occlusion and depth, scenes."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from amrvio.errors import ShapeError
from amrvio.sim import textures as tx
from amrvio.sim.render import SceneRenderer
from amrvio.sim.scene import Quad, Scene, make_scene
from amrvio.types.camera import PinholeCamera, RadTanCamera
from amrvio.types.lie import SE3, SO3

PINHOLE = PinholeCamera(752, 480, 458.654, 457.296, 367.215, 248.375)
RADTAN = RadTanCamera(752, 480, 458.654, 457.296, 367.215, 248.375,
                      k1=-0.28340811, k2=0.07395907, p1=0.00019359, p2=1.76187114e-05)
# Camera looking along world +x (camera z = world x, camera x = -world y, camera y = -world z).
R_FORWARD = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _rect(c0, a, b, tex_id, tpm, offset=(0.0, 0.0), radiance=1.0, two_sided=True):
    c0, a, b = (np.asarray(v, dtype=float) for v in (c0, a, b))
    return Quad(np.stack([c0, c0 + a, c0 + a + b, c0 + b]), tex_id, tpm, radiance, offset,
                two_sided)


def _scene(quads, textures):
    corners = np.concatenate([q.corners_world for q in quads])
    return Scene("test", tuple(quads), tuple(textures), corners.min(0), corners.max(0))


@pytest.fixture(scope="module")
def checker_scene():
    """A checkerboard wall (16-texel squares at 64 texels/m, i.e. 0.25 m) in the camera-frame plane
    z ~ 4 m, seen obliquely."""
    tex = tx.checkerboard(256, 16)
    wall = _rect((0.0, -3.0, -2.0), (0.0, 6.0, 0.0), (0.0, 0.0, 4.0), 0, 64.0, (-0.5, -0.5))
    # Tilt the wall: rotate it about z by 25 degrees, place it 4 m ahead.
    Rz = SO3.exp([0.0, 0.0, 0.45]).R
    c = wall.corners_world @ Rz.T + np.array([4.0, 0.0, 1.0])
    wall = Quad(c, 0, 64.0, 1.0, (-0.5, -0.5))
    return _scene([wall], [tex]), wall


def _corner_points(wall: Quad):
    # Checker boundaries lie half-way between texel centres: s = 16 k - 0.5 (see Quad docs).
    ks = np.arange(1, 24)
    ms = np.arange(1, 16)
    return np.array([wall.point_at(16 * k - 0.5, 16 * m - 0.5) for k in ks for m in ms])


@pytest.mark.parametrize("camera", [PINHOLE, RADTAN], ids=["pinhole", "radtan"])
def test_projected_points_land_where_drawn(checker_scene, camera):
    scene, wall = checker_scene
    T_world_cam = SE3(SO3(R_FORWARD @ SO3.exp([0.08, -0.05, 0.03]).R), np.array([0.3, 0.2, 1.1]))
    renderer = SceneRenderer(scene, camera)
    img = renderer.irradiance(T_world_cam)
    X = _corner_points(wall)
    uv = camera.project(T_world_cam.inverse().act(X))
    inside = camera.in_image(uv, border_px=15.0)
    assert inside.sum() > 40
    uv = uv[inside]
    rng = np.random.default_rng(3)
    guess = (uv + rng.uniform(-1.5, 1.5, uv.shape)).astype(np.float32).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    found = cv2.cornerSubPix(img.astype(np.float32), guess, (5, 5), (-1, -1), crit).reshape(-1, 2)
    err = np.linalg.norm(found - uv, axis=1)
    assert np.max(err) < 0.5
    assert np.median(err) < 0.1


def _raycast_depth(quads, camera, T_world_cam):
    """Independent reference: per-pixel ray / parallelogram intersection, nearest hit."""
    h, w = camera.height, camera.width
    us, vs = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    rays_c = np.stack([(us - camera.cx) / camera.fx, (vs - camera.cy) / camera.fy,
                       np.ones_like(us)], -1).reshape(-1, 3)
    R, o = T_world_cam.R, T_world_cam.t
    rays_w = rays_c @ R.T
    best = np.full(rays_c.shape[0], np.inf)
    best_id = np.full(rays_c.shape[0], -1)
    for i, q in enumerate(quads):
        c0, a, b = q.corners_world[0], q.axis_a, q.axis_b
        n = np.cross(a, b)
        den = rays_w @ n
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = ((c0 - o) @ n) / den  # X = o + lam * ray_w; ray has camera z = 1 -> lam = depth
        X = o + lam[:, None] * rays_w - c0
        # Solve X = alpha a + beta b in the plane (least squares on the 3 coordinates).
        G = np.array([[a @ a, a @ b], [a @ b, b @ b]])
        rhs = np.stack([X @ a, X @ b], axis=1)
        ab = np.linalg.solve(G, rhs.T).T
        hit = (lam > 0) & np.all((ab >= 0) & (ab <= 1), axis=1) & np.isfinite(lam)
        closer = hit & (lam < best)
        best[closer] = lam[closer]
        best_id[closer] = i
    return best.reshape(h, w), best_id.reshape(h, w)


def test_occlusion_and_depth_exact():
    # A wall 6 m ahead and a closed box 2.5 m ahead in front of it.
    textures = [tx.constant(8, 0.8), tx.constant(8, 0.2)]
    quads = [_rect((6.0, -15.0, -9.0), (0.0, 30.0, 0.0), (0.0, 0.0, 20.0), 0, 100.0, radiance=10.0)]
    lo, hi = np.array([2.5, -0.6, 0.4]), np.array([3.2, 0.5, 1.3])
    d = hi - lo
    ex, ey, ez = np.diag(d)
    # Outward normals a x b: +z, -y, +y, -x, +x, -z.
    faces = [(lo + ez, ex, ey), (lo, ex, ez), (lo + ey, ez, ex), (lo, ez, ey), (lo + ex, ey, ez),
             (lo, ey, ex)]
    for c0, a, b in faces:
        quads.append(_rect(c0, a, b, 1, 100.0, radiance=10.0, two_sided=False))
    scene = _scene(quads, textures)
    T_world_cam = SE3(SO3(R_FORWARD @ SO3.exp([0.1, 0.2, -0.05]).R), np.array([0.2, 0.1, 1.0]))
    renderer = SceneRenderer(scene, PINHOLE)
    img, depth = renderer.render(T_world_cam)
    ref_depth, ref_id = _raycast_depth(quads, PINHOLE, T_world_cam)
    assert np.isfinite(ref_depth).all()
    box_px = ref_id >= 1
    assert box_px.sum() > 5000  # the box covers part of the view and hides the wall there
    rel = np.abs(depth.astype(np.float64) - ref_depth) / ref_depth
    good = rel < 1e-4
    # Only pixel centres within float rounding of a silhouette edge may disagree.
    assert good.mean() > 0.999
    edge = cv2.dilate((ref_id != cv2.erode(ref_id.astype(np.float32), np.ones((3, 3))))
                      .astype(np.uint8), np.ones((3, 3))) > 0
    assert np.all(good | edge)
    expected_img = np.where(box_px, 2.0, 8.0)
    assert np.mean(np.isclose(img, expected_img, rtol=1e-5)) > 0.999


@pytest.fixture(scope="module")
def scenes():
    return {name: make_scene(name, seed=0) for name in ("corridor", "warehouse", "room")}


def test_scene_layouts(scenes):
    c = scenes["corridor"]
    extent = c.bounds_max - c.bounds_min
    assert extent[0] >= 40.0 and 2.3 <= extent[1] <= 2.8 and 2.9 <= extent[2] <= 3.1
    assert c.bounds_min[2] == pytest.approx(0.0) and c.floor_z == 0.0
    r = scenes["room"]
    assert np.allclose(r.bounds_max - r.bounds_min, [8.0, 8.0, 4.0], atol=0.05)
    w = scenes["warehouse"]
    assert w.bounds_max[2] >= 6.0 and w.bounds_max[0] - w.bounds_min[0] >= 40.0
    for s in scenes.values():
        assert len(s.textures) >= 6
        for t in s.textures:
            assert t.dtype == np.float32 and t.min() >= 0.0 and t.max() <= 1.0
        assert all(0 <= q.texture_id < len(s.textures) for q in s.quads)


@pytest.mark.parametrize("name", ["corridor", "warehouse", "room"])
def test_free_area_is_free(scenes, name):
    """No obstacle (any quad above the floor that is not a wall) intrudes into the free floor area."""
    s = scenes[name]
    lo, hi = s.free_xy_min, s.free_xy_max
    assert np.all(hi > lo)
    for q in s.quads:
        c = q.corners_world
        if np.all(c[:, 2] <= 0.01) or np.all(c[:, 2] >= 2.5):
            continue  # floor-level quads (floor, rug, thresholds) and the ceiling
        overlap = np.all(c[:, :2].max(axis=0) > lo) and np.all(c[:, :2].min(axis=0) < hi)
        assert not overlap, f"{name}: {q.name} intrudes into the free area"
    assert np.all(s.start_position_m[:2] >= lo) and np.all(s.start_position_m[:2] <= hi)


def test_landmarks_lie_on_surfaces(scenes):
    s = scenes["room"]
    pts = s.landmarks(200, np.random.default_rng(1))
    assert pts.shape == (200, 3)
    dist = np.full(200, np.inf)
    for q in s.quads:
        n = q.normal
        off = (pts - q.corners_world[0]) @ n
        G = np.array([[q.axis_a @ q.axis_a, q.axis_a @ q.axis_b],
                      [q.axis_a @ q.axis_b, q.axis_b @ q.axis_b]])
        rel = pts - q.corners_world[0]
        ab = np.linalg.solve(G, np.stack([rel @ q.axis_a, rel @ q.axis_b])).T
        inside = np.all((ab > -1e-9) & (ab < 1 + 1e-9), axis=1)
        dist = np.where(inside, np.minimum(dist, np.abs(off)), dist)
    assert np.all(dist < 1e-9)
    again = s.landmarks(200, np.random.default_rng(1))
    assert np.array_equal(pts, again)


@pytest.mark.parametrize("name", ["corridor", "warehouse", "room"])
def test_closed_scene_renders_without_holes(scenes, name):
    """Scenes are closed: from inside, every pixel sees a surface (no cracks between pieces)."""
    s = scenes[name]
    renderer = SceneRenderer(s, PINHOLE)
    start = s.start_position_m + np.array([0.0, 0.0, 0.8])
    for yaw, pitch in ((0.0, 0.15), (0.7, -0.2), (2.0, 0.0)):
        R = SO3.exp([0.0, 0.0, yaw]).R @ R_FORWARD @ SO3.exp([pitch, 0.0, 0.0]).R
        img, depth = renderer.render(SE3(SO3(R), start))
        assert np.isfinite(depth).all(), f"{name}: holes at yaw {yaw}"
        assert img.min() > 0.0
        assert 0.1 < float(np.median(img)) * 0.01 < 0.9  # sensible exposure at 10 ms


def test_scene_determinism_and_errors():
    a = make_scene("room", seed=3)
    b = make_scene("room", seed=3)
    assert len(a.quads) == len(b.quads)
    assert all(np.array_equal(qa.corners_world, qb.corners_world) for qa, qb in
               zip(a.quads, b.quads, strict=True))
    assert all(np.array_equal(ta, tb) for ta, tb in zip(a.textures, b.textures, strict=True))
    with pytest.raises(ShapeError):
        make_scene("garage")
    with pytest.raises(ShapeError):
        Quad(np.array([[0, 0, 0], [1, 0, 0], [1, 2, 0], [0, 1, 0]], float), 0, 10.0)


def test_depth_and_radtan_canvas_consistency(checker_scene):
    scene, _ = checker_scene
    T_world_cam = SE3(SO3(R_FORWARD), np.array([0.0, 0.0, 1.0]))
    d_pin = SceneRenderer(scene, PINHOLE).depth(T_world_cam)
    d_rad = SceneRenderer(scene, RADTAN).depth(T_world_cam)
    # Pixel at the principal point sees the same ray in both models.
    v, u = int(round(PINHOLE.cy)), int(round(PINHOLE.cx))
    assert d_rad[v, u] == pytest.approx(d_pin[v, u], rel=2e-3)
    # Radtan depth is the depth of the undistorted ray: check against a reprojection.
    uv = np.array([[100.0, 80.0], [650.0, 400.0]])
    rays = RADTAN.unproject(uv)
    ideal = PINHOLE.project(rays)
    for (ud, vd), (ui, vi) in zip(uv.astype(int), ideal, strict=True):
        z_ref = d_pin[int(round(vi)), int(round(ui))]
        assert d_rad[vd, ud] == pytest.approx(z_ref, rel=5e-3)


def test_textures_are_periodic_and_prefiltered():
    photo = tx.load_photo("brick", 256)
    assert photo.shape == (256, 256) and photo.dtype == np.float32 and not photo.flags.writeable
    assert 0.03 - 1e-6 <= photo.min() and photo.max() <= 0.9 + 1e-6
    # Mirror tiling: wrapping around is seamless (the last column repeats the first).
    assert np.array_equal(photo[:, 0], photo[:, -1]) and np.array_equal(photo[0], photo[-1])
    noise = tx.procedural_noise(256, seed=5)
    assert np.array_equal(noise, tx.procedural_noise(256, seed=5))
    inner = np.abs(np.diff(noise, axis=1)).mean()
    seam = np.abs(noise[:, 0] - noise[:, -1]).mean()
    assert seam < 2.0 * inner  # no discontinuity at the wrap
    mip = tx.MipTexture.build(noise)
    assert [lv.shape[0] for lv in mip.levels] == [256, 128, 64, 32, 16, 8]
    for lv in mip.levels:
        assert abs(float(lv.mean()) - float(noise.mean())) < 1e-3
    with pytest.raises(ShapeError):
        tx.checkerboard(100, 16)
    with pytest.raises(ShapeError):
        tx.load_photo("not-a-photo", 256)


@pytest.mark.parametrize("ss", [2, 3])
def test_supersampling_antialiases_and_keeps_geometry(checker_scene, ss):
    scene, wall = checker_scene
    T_world_cam = SE3(SO3(R_FORWARD @ SO3.exp([0.08, -0.05, 0.03]).R), np.array([0.3, 0.2, 1.1]))
    plain = SceneRenderer(scene, PINHOLE)
    fine = SceneRenderer(scene, PINHOLE, supersample=ss)
    img, depth = fine.render(T_world_cam)
    assert img.shape == (480, 752)
    # Geometry unchanged: checker corners still land on the projections.
    X = _corner_points(wall)
    uv = PINHOLE.project(T_world_cam.inverse().act(X))
    uv = uv[PINHOLE.in_image(uv, border_px=15.0)]
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    found = cv2.cornerSubPix(img, (uv + 0.7).astype(np.float32).reshape(-1, 1, 2), (5, 5),
                             (-1, -1), crit).reshape(-1, 2)
    assert np.max(np.linalg.norm(found - uv, axis=1)) < 0.5
    # Depth is exact inside the plane (same as the 1x render) and the wall silhouette is a
    # partial-coverage blend: values strictly between the void (0) and the surface.
    d0 = plain.depth(T_world_cam)
    interior = cv2.erode(np.isfinite(d0).astype(np.uint8), np.ones((3, 3))) > 0
    assert interior.mean() > 0.5
    assert np.allclose(depth[interior], d0[interior], rtol=1e-5)
    # A uniform quad against the void: edge pixels get partial coverage only when supersampling.
    quad = _rect((5.0, -1.0, 0.2), (0.3, 2.0, 0.0), (0.0, 0.4, 1.5), 0, 10.0, radiance=1.0)
    flat = _scene([quad], [tx.constant(8, 0.8)])
    T = SE3(SO3(R_FORWARD), np.array([0.0, 0.0, 1.0]))
    for r, expect_partial in ((SceneRenderer(flat, PINHOLE), False),
                              (SceneRenderer(flat, PINHOLE, supersample=ss), True)):
        im = r.irradiance(T)
        partial = (im > 1e-6) & (im < 0.8 - 1e-6)
        assert bool(partial.any()) == expect_partial
        assert set(np.unique(np.round(im[partial] / 0.8 * ss * ss))) <= set(range(1, ss * ss))
        assert np.all(np.isclose(im[partial] / 0.8 * ss * ss, np.round(im[partial] / 0.8 * ss * ss),
                                 atol=1e-4))
