"""Simulated indoor scenes made of textured planar quads (world frame: z up, floor at z = 0).

A :class:`Quad` is a planar parallelogram ``c0, c1 = c0 + a, c2 = c0 + a + b, c3 = c0 + b`` carrying a
periodic texture tiled at ``texels_per_m``. Texture coordinates (level-0 texels, texel ``i`` centred at
``s = i``) of a world point ``X`` on the quad are

    s = (X - c0) . a_hat * texels_per_m + offset_s,   t = (X - c0) . b_hat * texels_per_m + offset_t,

and its linear scene radiance is ``radiance * texture(s, t)``. Radiance units: a value of ``1 / t``
fills the sensor's range at exposure ``t`` seconds and unit gain (see image_formation).

Scenes: ``corridor`` (indoor AMR corridor, 2.4 m wide, 3 m high, 50 m long, doorways, posters,
boxes, ceiling lights), ``warehouse`` (3 m aisle between 6 m racks with boxes), ``room`` (8 x 8 x 4 m
with boxes, tables and posters, like the EuRoC Vicon room), ``wall`` (one textured planar wall,
14 x 5 m, at x = 3 m, tiled with photographs and noise textures, and a dim floor: a scene dominated
by one plane, in front of which a camera is carried at 1-3 m). The robot drives along +x in the
corridor and the aisle; in front of the wall +x points at the wall.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.sim import textures as tx

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]

SceneName = Literal["corridor", "warehouse", "room", "wall"]
SCENE_NAMES: tuple[str, ...] = ("corridor", "warehouse", "room", "wall")

# Radiance of a fully lit surface: albedo 1 saturates the sensor at 10 ms exposure and unit gain.
BASE_RADIANCE = 100.0
TEXTURE_SIZE = 1024


@dataclass(frozen=True, slots=True, eq=False)
class Quad:
    """A textured planar parallelogram. corners_world: (4, 3) in order c0, c1, c2, c3 (c2 = c1 + c3 - c0).

    two_sided=False means the quad is a face of a closed solid and is culled when seen from behind
    (behind = the side opposite to ``normal = a x b``).
    """

    corners_world: F64
    texture_id: int
    texels_per_m: float
    radiance: float = BASE_RADIANCE
    offset_texels: tuple[float, float] = (0.0, 0.0)
    two_sided: bool = True
    name: str = ""

    def __post_init__(self) -> None:
        c = np.array(self.corners_world, dtype=np.float64)
        if c.shape != (4, 3) or not np.all(np.isfinite(c)):
            raise ShapeError(f"Quad corners must be a finite (4, 3) array, got {c.shape}")
        a, b = c[1] - c[0], c[3] - c[0]
        if np.linalg.norm(c[2] - (c[0] + a + b)) > 1e-6 * (1.0 + np.abs(c).max()):
            raise ShapeError("Quad corners must form a parallelogram: c2 == c1 + c3 - c0")
        if np.linalg.norm(np.cross(a, b)) < 1e-9:
            raise ShapeError("Quad is degenerate (zero area)")
        if not (self.texels_per_m > 0 and np.isfinite(self.texels_per_m)):
            raise ShapeError(f"texels_per_m must be positive, got {self.texels_per_m}")
        if not (self.radiance >= 0 and np.isfinite(self.radiance)):
            raise ShapeError(f"radiance must be finite and >= 0, got {self.radiance}")
        if self.texture_id < 0:
            raise ShapeError("texture_id must be >= 0")
        c.setflags(write=False)
        object.__setattr__(self, "corners_world", c)

    @property
    def origin(self) -> F64:
        return np.array(self.corners_world[0])

    @property
    def axis_a(self) -> F64:
        """Edge c0 -> c1 (m)."""
        return np.array(self.corners_world[1] - self.corners_world[0])

    @property
    def axis_b(self) -> F64:
        """Edge c0 -> c3 (m)."""
        return np.array(self.corners_world[3] - self.corners_world[0])

    @property
    def normal(self) -> F64:
        n = np.cross(self.axis_a, self.axis_b)
        return np.asarray(n / np.linalg.norm(n), dtype=np.float64)

    @property
    def area_m2(self) -> float:
        return float(np.linalg.norm(np.cross(self.axis_a, self.axis_b)))

    def texture_coords(self, points_world: ArrayLike) -> F64:
        """(N, 3) points on the quad's plane -> (N, 2) level-0 texture coordinates (s, t).

        Exact for rectangles; for a skewed parallelogram the coordinates are along a_hat and b_hat.
        """
        p = np.asarray(points_world, dtype=np.float64).reshape(-1, 3) - self.corners_world[0]
        a, b = self.axis_a, self.axis_b
        ah, bh = a / np.linalg.norm(a), b / np.linalg.norm(b)
        st = np.stack([p @ ah, p @ bh], axis=1) * self.texels_per_m
        return np.asarray(st + np.asarray(self.offset_texels), dtype=np.float64)

    def point_at(self, s: float, t: float) -> F64:
        """World point (3,) of texture coordinate (s, t) on a rectangular quad."""
        a, b = self.axis_a, self.axis_b
        ah, bh = a / np.linalg.norm(a), b / np.linalg.norm(b)
        ds = (s - self.offset_texels[0]) / self.texels_per_m
        dt = (t - self.offset_texels[1]) / self.texels_per_m
        return np.asarray(self.corners_world[0] + ds * ah + dt * bh, dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class Scene:
    """A static scene. ``textures[q.texture_id]`` is the (S, S) float32 albedo map of quad ``q``.

    ``start_position_m`` / ``start_yaw_rad``: a suggested robot start on the floor; the free drive
    runs ``drive_length_m`` along ``drive_direction`` (corridor and aisle: +x). ``free_xy_min`` /
    ``free_xy_max``: the floor rectangle that is free of obstacles for a robot path.
    """

    name: str
    quads: tuple[Quad, ...]
    textures: tuple[F32, ...]
    bounds_min: F64
    bounds_max: F64
    floor_z: float = 0.0
    start_position_m: F64 = field(default_factory=lambda: np.zeros(3))
    start_yaw_rad: float = 0.0
    drive_direction: F64 = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    drive_length_m: float = 10.0
    free_xy_min: F64 = field(default_factory=lambda: np.zeros(2))
    free_xy_max: F64 = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self) -> None:
        for q in self.quads:
            if q.texture_id >= len(self.textures):
                raise ShapeError(f"quad {q.name!r} uses texture {q.texture_id}, scene has "
                                 f"{len(self.textures)}")
        for t in self.textures:
            if t.ndim != 2 or t.shape[0] != t.shape[1]:
                raise ShapeError("scene textures must be square (S, S) arrays")

    def landmarks(self, n: int, rng: np.random.Generator, emissive_ok: bool = False) -> F64:
        """(n, 3) points sampled uniformly (by area) on textured surfaces.

        Light panels (radiance above 3 x BASE_RADIANCE) are skipped unless ``emissive_ok``.
        """
        if n < 0:
            raise ShapeError("n must be >= 0")
        quads = [q for q in self.quads if emissive_ok or q.radiance <= 3.0 * BASE_RADIANCE]
        areas = np.array([q.area_m2 for q in quads])
        idx = rng.choice(len(quads), size=n, p=areas / areas.sum())
        uv = rng.random((n, 2))
        out = np.empty((n, 3))
        for k, (i, (u, v)) in enumerate(zip(idx, uv, strict=True)):
            q = quads[int(i)]
            out[k] = q.corners_world[0] + u * q.axis_a + v * q.axis_b
        return out


class _Builder:
    """Accumulates quads and textures for one scene (seeded)."""

    def __init__(self, seed: int) -> None:
        self.rng = np.random.default_rng(seed)
        self.seed = seed
        self.quads: list[Quad] = []
        self.textures: list[F32] = []
        self.tex_ids: dict[str, int] = {}

    def tex(self, key: str) -> int:
        """Texture id of ``key``: a photo name, "noise<k>", "check<n>" or "const<v>"."""
        if key in self.tex_ids:
            return self.tex_ids[key]
        if key in tx.PHOTO_FILES:
            t = tx.load_photo(key, TEXTURE_SIZE)
        elif key.startswith("noise"):
            k = int(key[5:])
            t = tx.procedural_noise(TEXTURE_SIZE, seed=self.seed * 1000 + k, beta=1.3 + 0.15 * (k % 4))
        elif key.startswith("check"):
            t = tx.checkerboard(256, int(key[5:]))
        elif key.startswith("const"):
            t = tx.constant(8, float(key[5:]))
        else:
            raise ShapeError(f"unknown texture key {key!r}")
        self.tex_ids[key] = len(self.textures)
        self.textures.append(t)
        return self.tex_ids[key]

    def rect(
        self,
        c0: ArrayLike,
        a: ArrayLike,
        b: ArrayLike,
        tex: str,
        tpm: float,
        shade: float = 1.0,
        two_sided: bool = True,
        name: str = "",
    ) -> None:
        p0 = np.asarray(c0, dtype=np.float64)
        va, vb = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        tid = self.tex(tex)
        size = self.textures[tid].shape[0]
        off = (float(self.rng.uniform(0, size)), float(self.rng.uniform(0, size)))
        corners = np.stack([p0, p0 + va, p0 + va + vb, p0 + vb])
        self.quads.append(
            Quad(corners, tid, tpm, BASE_RADIANCE * shade, off, two_sided, name)
        )

    def poster(self, top_left: ArrayLike, right: ArrayLike, width_m: float, height_m: float,
               tex: str, name: str = "poster") -> None:
        """An upright picture: one unmirrored copy of the photo across ``width_m``."""
        r = np.asarray(right, dtype=np.float64)
        r = r / np.linalg.norm(r)
        tid = self.tex(tex)
        half = self.textures[tid].shape[0] / 2
        p0 = np.asarray(top_left, dtype=np.float64)
        a, b = r * width_m, np.array([0.0, 0.0, -height_m])
        corners = np.stack([p0, p0 + a, p0 + a + b, p0 + b])
        self.quads.append(Quad(corners, tid, half / width_m, BASE_RADIANCE * 0.8, (0.0, 0.0), True,
                               name))

    def box(self, lo: ArrayLike, hi: ArrayLike, tex: str, tpm: float, name: str = "box",
            bottom: bool = False) -> None:
        """Axis-aligned box; faces have outward normals (a x b) and are back-face culled."""
        x0, y0, z0 = (float(v) for v in np.asarray(lo))
        x1, y1, z1 = (float(v) for v in np.asarray(hi))
        dx, dy, dz = x1 - x0, y1 - y0, z1 - z0
        ex, ey, ez = np.array([dx, 0, 0]), np.array([0, dy, 0]), np.array([0, 0, dz])
        vary = float(self.rng.uniform(0.85, 1.1))
        # (origin, a, b) with a x b pointing outwards; shade from the overhead-light orientation.
        faces = [
            ((x0, y0, z1), ex, ey, 1.0),  # top (+z)
            ((x0, y0, z0), ex, ez, 0.75),  # -y
            ((x0, y1, z0), ez, ex, 0.7),  # +y
            ((x0, y0, z0), ez, ey, 0.65),  # -x
            ((x1, y0, z0), ey, ez, 0.8),  # +x
        ]
        if bottom:
            faces.append(((x0, y0, z0), ey, ex, 0.35))
        for origin, a, b, shade in faces:
            self.rect(origin, a, b, tex, tpm, shade * vary, two_sided=False, name=name)

    def scene(self, name: str, **kw: object) -> Scene:
        corners = np.concatenate([q.corners_world for q in self.quads])
        return Scene(
            name=name,
            quads=tuple(self.quads),
            textures=tuple(self.textures),
            bounds_min=corners.min(axis=0),
            bounds_max=corners.max(axis=0),
            **kw,  # type: ignore[arg-type]
        )


_POSTERS = ("camera", "astronaut", "rocket", "motorcycle", "chelsea", "coffee", "coins", "horse",
            "moon", "page", "text")
_BOX_TEX = ("noise3", "noise4", "coffee", "text", "noise5", "coins", "page", "noise6")


def _corridor(seed: int) -> Scene:
    b = _Builder(seed)
    rng = b.rng
    x0, x1, hw, h = -5.0, 45.0, 1.2, 3.0
    length = x1 - x0
    b.rect((x0, -hw, 0), (length, 0, 0), (0, 2 * hw, 0), "noise0", 300.0, 0.9, name="floor")
    b.rect((x0, -hw, h), (0, 2 * hw, 0), (length, 0, 0), "noise1", 200.0, 0.55, name="ceiling")
    # Ceiling light panels every 4 m, 5 mm below the ceiling.
    for x in np.arange(x0 + 2.0, x1 - 1.0, 4.0):
        b.rect((x, -0.2, h - 0.005), (0, 0.4, 0), (1.2, 0, 0), "const0.9", 50.0, 25.0, name="light")
    b.rect((x0, -hw, 0), (0, 2 * hw, 0), (0, 0, h), "astronaut", 300.0, 0.8, name="end_wall")
    b.rect((x1, -hw, 0), (0, 2 * hw, 0), (0, 0, h), "camera", 300.0, 0.8, name="end_wall")
    door_w, door_h, recess = 1.0, 2.1, 0.12
    for side in (-1.0, 1.0):
        y = side * hw
        wall_tex = "brick" if side < 0 else "noise2"
        doors = [float(x) for x in np.arange(x0 + 6.0 + (0.0 if side < 0 else 4.0), x1 - 3.0, 8.0)]
        edges = [x0] + [v for d in doors for v in (d, d + door_w)] + [x1]
        for xa, xb in zip(edges[0::2], edges[1::2], strict=True):
            b.rect((xa, y, 0), (xb - xa, 0, 0), (0, 0, h), wall_tex, 400.0, 0.75, name="wall")
        for d in doors:
            b.rect((d, y, door_h), (door_w, 0, 0), (0, 0, h - door_h), wall_tex, 400.0, 0.75,
                   name="lintel")
            yr = y + side * recess
            b.rect((d, yr, 0), (door_w, 0, 0), (0, 0, door_h), "noise7", 250.0, 0.6, name="door")
            b.rect((d, y, 0), (0, side * recess, 0), (0, 0, door_h), "noise2", 300.0, 0.6,
                   name="jamb")
            b.rect((d + door_w, y, 0), (0, side * recess, 0), (0, 0, door_h), "noise2", 300.0, 0.6,
                   name="jamb")
            b.rect((d, y, door_h), (door_w, 0, 0), (0, side * recess, 0), "noise2", 300.0, 0.5,
                   name="jamb")
            b.rect((d, y, 0), (door_w, 0, 0), (0, side * recess, 0), "noise0", 300.0, 0.9,
                   name="threshold")
        # Posters 5 mm in front of the wall, between the doors.
        for xp in np.arange(x0 + 2.0, x1 - 2.0, 3.3):
            if any(d - 1.0 < xp < d + door_w + 0.2 for d in doors):
                continue
            w, hh = float(rng.uniform(0.5, 0.9)), float(rng.uniform(0.4, 0.7))
            zp = float(rng.uniform(1.0, 1.6))
            yp = y - side * 0.005
            key = _POSTERS[int(rng.integers(len(_POSTERS)))]
            # Seen from the corridor, "right" is -x on the -y wall and +x on the +y wall.
            right = (-1.0, 0.0, 0.0) if side < 0 else (1.0, 0.0, 0.0)
            x_left = xp + w if side < 0 else xp
            b.poster((x_left, yp, zp + hh), right, w, hh, key)
        # Boxes along the wall, away from doors.
        for xb in np.arange(x0 + 3.0, x1 - 2.0, 2.6):
            xb = xb + float(rng.uniform(-0.4, 0.4))
            sx, sy, sz = (float(v) for v in rng.uniform([0.35, 0.3, 0.25], [0.8, 0.5, 0.8]))
            if any(d - sx - 0.3 < xb < d + door_w + 0.3 for d in doors) or rng.random() < 0.3:
                continue
            ylo = y - sy - 0.02 if side > 0 else y + 0.02
            key = _BOX_TEX[int(rng.integers(len(_BOX_TEX)))]
            b.box((xb, ylo, 0), (xb + sx, ylo + sy, sz), key, 500.0)
    return b.scene(
        "corridor",
        start_position_m=np.array([0.0, 0.0, 0.0]),
        start_yaw_rad=0.0,
        drive_length_m=40.0,
        free_xy_min=np.array([x0 + 1.0, -0.5]),
        free_xy_max=np.array([x1 - 2.0, 0.5]),
    )


def _warehouse(seed: int) -> Scene:
    b = _Builder(seed)
    rng = b.rng
    x0, x1, aisle, depth, rack_h, roof = -5.0, 45.0, 1.5, 1.1, 6.0, 8.0
    yw = aisle + depth + 0.1
    b.rect((x0, -yw, 0), (x1 - x0, 0, 0), (0, 2 * yw, 0), "noise0", 300.0, 0.9, name="floor")
    b.rect((x0, -yw, roof), (0, 2 * yw, 0), (x1 - x0, 0, 0), "noise1", 150.0, 0.4, name="roof")
    for x in np.arange(x0 + 2.0, x1 - 1.0, 5.0):
        b.rect((x, -0.3, roof - 0.05), (0, 0.6, 0), (1.5, 0, 0), "const0.9", 50.0, 30.0,
               name="light")
    b.rect((x0, -yw, 0), (0, 2 * yw, 0), (0, 0, roof), "brick", 300.0, 0.7, name="end_wall")
    b.rect((x1, -yw, 0), (0, 2 * yw, 0), (0, 0, roof), "grass", 250.0, 0.7, name="end_wall")
    bay = 2.7
    levels = (0.12, 1.5, 3.0, 4.5)
    for side in (-1.0, 1.0):
        yf = side * aisle  # rack front
        yb = side * (aisle + depth)  # rack back
        b.rect((x0, yb + side * 0.1, 0), (x1 - x0, 0, 0), (0, 0, roof), "noise2", 250.0, 0.5,
               name="back_wall")
        xs = np.arange(x0 + 1.0, x1 - 2.0 + 1e-9, bay)
        for xu in xs:  # front and back posts of each rack frame
            for yp in (yf, yb):
                b.box((xu - 0.04, yp - 0.04, 0), (xu + 0.04, yp + 0.04, rack_h), "const0.35", 100.0,
                      name="upright")
        for z in levels:  # beams (front only: a flat strip)
            b.box((xs[0], yf - (0.06 if side > 0 else 0.0), z), (xs[-1], yf + (0.06 if side < 0
                  else 0.0), z + 0.1), "const0.6", 100.0, name="beam")
        for xa in xs[:-1]:
            for z in levels:
                x = xa + 0.1
                while x < xa + bay - 0.4:
                    sx = float(rng.uniform(0.7, 1.3))
                    if x + sx > xa + bay - 0.1:
                        break
                    if rng.random() < 0.8:
                        sy = float(rng.uniform(0.6, depth - 0.05))
                        sz = float(rng.uniform(0.4, 1.2))
                        y_in = yf + side * float(rng.uniform(0.02, depth - sy))
                        lo_y, hi_y = sorted((y_in, y_in + side * sy))
                        key = _BOX_TEX[int(rng.integers(len(_BOX_TEX)))]
                        b.box((x, lo_y, z + 0.1), (x + sx, hi_y, z + 0.1 + sz), key, 450.0)
                    x += sx + float(rng.uniform(0.05, 0.3))
    return b.scene(
        "warehouse",
        start_position_m=np.array([0.0, 0.0, 0.0]),
        drive_length_m=38.0,
        free_xy_min=np.array([x0 + 1.0, -aisle + 0.5]),
        free_xy_max=np.array([x1 - 2.0, aisle - 0.5]),
    )


def _room(seed: int) -> Scene:
    b = _Builder(seed)
    rng = b.rng
    s, h = 4.0, 4.0
    b.rect((-s, -s, 0), (2 * s, 0, 0), (0, 2 * s, 0), "noise0", 300.0, 0.9, name="floor")
    b.rect((-s, -s, h), (0, 2 * s, 0), (2 * s, 0, 0), "noise1", 150.0, 0.5, name="ceiling")
    b.rect((-1.5, -1.0, 0.002), (3.0, 0, 0), (0, 2.0, 0), "gravel", 350.0, 0.8, name="rug")
    for x in (-2.0, 2.0):
        for y in (-2.0, 2.0):
            b.rect((x - 0.4, y - 0.4, h - 0.01), (0, 0.8, 0), (0.8, 0, 0), "const0.9", 50.0, 25.0,
                   name="light")
    walls = [
        ((-s, -s, 0), (2 * s, 0, 0), "brick"),
        ((s, -s, 0), (0, 2 * s, 0), "noise2"),
        ((s, s, 0), (-2 * s, 0, 0), "noise9"),
        ((-s, s, 0), (0, -2 * s, 0), "brick"),
    ]
    for origin, along, key in walls:
        b.rect(origin, along, (0, 0, h), key, 350.0, 0.7, name="wall")
        o, a = np.asarray(origin, dtype=float), np.asarray(along, dtype=float)
        inward = np.cross((0, 0, 1.0), a / np.linalg.norm(a))
        for k in range(3):
            w, hh = float(rng.uniform(0.8, 1.4)), float(rng.uniform(0.6, 1.0))
            c = o + a * (0.2 + 0.27 * k) + inward * 0.005 + np.array([0, 0, rng.uniform(1.6, 2.6)])
            key2 = _POSTERS[int(rng.integers(len(_POSTERS)))]
            a_hat = a / np.linalg.norm(a)  # seen from inside, "right" is -a_hat
            b.poster(c + a_hat * w, -a_hat, w, hh, key2)
    # Clutter near the walls: boxes and tables, leaving the centre free for the robot.
    for k in range(12):
        ang = 2 * np.pi * k / 12 + float(rng.uniform(-0.15, 0.15))
        r = float(rng.uniform(2.9, 3.4))
        cx, cy = r * np.cos(ang), r * np.sin(ang)
        sx, sy, sz = (float(v) for v in rng.uniform([0.3, 0.3, 0.3], [0.8, 0.8, 1.2]))
        key = _BOX_TEX[int(rng.integers(len(_BOX_TEX)))]
        b.box((cx - sx / 2, cy - sy / 2, 0), (cx + sx / 2, cy + sy / 2, sz), key, 450.0)
    for cx, cy in ((-2.6, 0.0), (2.6, 0.8)):
        top_z, tw, td = 0.75, 1.2, 0.7
        b.box((cx - td / 2, cy - tw / 2, top_z - 0.04), (cx + td / 2, cy + tw / 2, top_z),
              "noise7", 400.0, name="table", bottom=True)
        for lx in (-1, 1):
            for ly in (-1, 1):
                px, py = cx + lx * (td / 2 - 0.05), cy + ly * (tw / 2 - 0.05)
                b.box((px - 0.025, py - 0.025, 0), (px + 0.025, py + 0.025, top_z - 0.04),
                      "const0.2", 100.0, name="leg")
        b.box((cx - 0.15, cy - 0.2, top_z), (cx + 0.15, cy + 0.1, top_z + 0.25), "coffee", 900.0,
              name="item")
    return b.scene(
        "room",
        start_position_m=np.array([-1.4, -1.4, 0.0]),
        start_yaw_rad=0.0,
        drive_length_m=2.8,
        free_xy_min=np.array([-1.9, -1.9]),
        free_xy_max=np.array([1.9, 1.9]),
    )


WALL_X_M = 3.0  # the wall scene's wall is the plane x = WALL_X_M (normal -x, towards the camera)


def _wall(seed: int) -> Scene:
    """One planar wall (x = WALL_X_M, y in [-7, 7] m, z in [0, 5] m) made of 14 x 5 coplanar 1 m
    tiles, each a randomly placed crop of a photograph, noise, brick or gravel texture (neighbours
    differ), so the wall has corners everywhere and no repeated pattern. The tiles share one plane
    exactly (no poster offset): every wall pixel obeys one homography. A dim floor lies in front of
    it; nothing else is in the scene."""
    b = _Builder(seed)
    xw, half_w, h, cols, rows = WALL_X_M, 7.0, 5.0, 14, 5
    b.rect((-4.0, -half_w, 0), (xw + 4.0, 0, 0), (0, 2 * half_w, 0), "noise0", 300.0, 0.5,
           name="floor")
    # dark or flat photographs (rocket: night sky, horse: a silhouette) are left out
    keys = ("camera", "noise2", "astronaut", "brick", "motorcycle", "noise9", "chelsea", "gravel",
            "coffee", "noise5", "coins", "noise7", "page", "noise3", "text", "moon", "noise8")
    tw, th = 2.0 * half_w / cols, h / rows
    for j in range(rows):
        for i in range(cols):
            key = keys[(i + 5 * j) % len(keys)]
            shade = float(b.rng.uniform(0.65, 0.85))
            # seen from the front (looking along +x), image right is -y and image down is -z
            b.rect((xw, half_w - i * tw, h - j * th), (0, -tw, 0), (0, 0, -th), key, 400.0, shade,
                   name="wall")
    return b.scene(
        "wall",
        start_position_m=np.array([0.0, 0.0, 0.0]),
        start_yaw_rad=0.0,
        drive_length_m=1.8,
        free_xy_min=np.array([-0.3, -3.0]),
        free_xy_max=np.array([xw - 1.1, 3.0]),
    )


def make_scene(name: SceneName | str, seed: int = 0) -> Scene:
    """Build the named scene. Same ``seed`` -> identical geometry and textures."""
    if name == "corridor":
        return _corridor(seed)
    if name == "warehouse":
        return _warehouse(seed)
    if name == "room":
        return _room(seed)
    if name == "wall":
        return _wall(seed)
    raise ShapeError(f"unknown scene {name!r}; choose one of {', '.join(SCENE_NAMES)}")
