"""A room of axis-aligned textured boxes with baked high-dynamic-range lighting, ray-cast per pixel.

World frame: x right, y down, z forward (the camera's axes at rest). Radiance is
in arbitrary linear units: ~0.001-0.02 in the dim ambient light, ~1 under the
spotlights and ~50 on the emissive window, so it spans more than 4 decades.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numba
import numpy as np

TEXELS_PER_M = 100.0
ATLAS_WIDTH = 4096
PAD = 2


@dataclass(frozen=True)
class Box:
    """Axis-aligned box [lo, hi] (m). `inside`: seen from within (the room's walls).
    `emission` > 0 makes it a light source of that radiance (times its albedo)."""

    lo: tuple
    hi: tuple
    inside: bool = False
    emission: float = 0.0


@dataclass(frozen=True)
class Spotlight:
    """Gaussian pool of light: peak irradiance, centre (m), radius (std, m)."""

    power: float
    centre: tuple
    radius_m: float


DEFAULT_BOXES = (
    Box((-4.0, -2.5, -2.0), (4.0, 2.5, 5.0), inside=True),  # the room
    Box((-1.3, 0.2, 2.0), (-0.5, 1.3, 2.6)),
    Box((0.5, -0.7, 1.7), (1.1, 0.3, 2.1)),
    Box((-0.4, 0.9, 3.1), (1.0, 2.5, 3.7)),
    Box((1.8, -1.9, 4.9), (2.8, -0.9, 4.98), emission=50.0),  # a bright window
)
DEFAULT_LIGHTS = (
    Spotlight(1.5, (2.3, -1.0, 5.0), 0.55),
    Spotlight(1.0, (-0.9, 0.4, 2.0), 0.25),
    Spotlight(0.6, (-2.5, 1.0, 5.0), 0.4),
)
AMBIENT = 0.02


def _albedo_texture(h: int, w: int, rng: np.random.Generator) -> np.ndarray:
    """Corner-rich piecewise-constant albedo in [0.05, 0.95]: random polygons, discs and bars."""
    tex = np.full((h, w), rng.uniform(0.15, 0.5), np.float32)
    n_shapes = max(3, int(h * w / 2500))
    for _ in range(n_shapes):
        value = float(rng.uniform(0.05, 0.95))
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        size = rng.uniform(4, 35)
        kind = rng.integers(3)
        if kind == 0:
            angles = np.sort(rng.uniform(0, 2 * np.pi, rng.integers(3, 6)))
            radii = size * rng.uniform(0.5, 1.0, len(angles))
            pts = np.stack([cx + radii * np.cos(angles), cy + radii * np.sin(angles)], 1)
            cv2.fillPoly(tex, [pts.astype(np.int32)], value)
        elif kind == 1:
            cv2.circle(tex, (int(cx), int(cy)), int(size * 0.6), value, -1)
        else:
            ww, hh = size * rng.uniform(0.3, 1.5), size * rng.uniform(0.3, 1.5)
            cv2.rectangle(tex, (int(cx - ww), int(cy - hh)), (int(cx + ww), int(cy + hh)), value, -1)
    return cv2.GaussianBlur(tex, (0, 0), 0.8)


class Scene:
    """Boxes with a radiance texture atlas; `render` ray-casts a camera pose to radiance."""

    def __init__(self, rng: np.random.Generator, boxes=DEFAULT_BOXES, lights=DEFAULT_LIGHTS, ambient=AMBIENT):
        self.boxes = boxes
        self.lo = np.array([b.lo for b in boxes], np.float32)
        self.hi = np.array([b.hi for b in boxes], np.float32)
        n_faces = 6 * len(boxes)
        self.face_offset = np.zeros((n_faces, 2), np.float32)  # atlas x, y of the tile
        self.face_size = np.ones((n_faces, 2), np.float32)  # tile width, height [texels]
        self.face_uv_axes = np.zeros((n_faces, 2), np.int64)
        self.face_uv_lo = np.zeros((n_faces, 2), np.float32)
        tiles = []
        for b, box in enumerate(boxes):
            for axis in range(3):
                u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
                w = max(2, int(np.ceil((box.hi[u_ax] - box.lo[u_ax]) * TEXELS_PER_M)))
                h = max(2, int(np.ceil((box.hi[v_ax] - box.lo[v_ax]) * TEXELS_PER_M)))
                for side in range(2):
                    f = b * 6 + axis * 2 + side
                    self.face_uv_axes[f] = (u_ax, v_ax)
                    self.face_uv_lo[f] = (box.lo[u_ax], box.lo[v_ax])
                    self.face_size[f] = (w, h)
                    plane = box.hi[axis] if side else box.lo[axis]
                    tiles.append((f, self._face_radiance(box, axis, plane, w, h, rng, lights, ambient)))
        self.atlas = self._pack(tiles)

    @staticmethod
    def _face_radiance(box, axis, plane, w, h, rng, lights, ambient) -> np.ndarray:
        albedo = _albedo_texture(h, w, rng)
        if box.emission > 0:
            return (box.emission * (0.6 + 0.4 * albedo)).astype(np.float32)
        u_ax, v_ax = (axis + 1) % 3, (axis + 2) % 3
        pos = np.zeros((h, w, 3), np.float32)
        pos[..., u_ax] = box.lo[u_ax] + (np.arange(w)[None, :] + 0.5) / TEXELS_PER_M
        pos[..., v_ax] = box.lo[v_ax] + (np.arange(h)[:, None] + 0.5) / TEXELS_PER_M
        pos[..., axis] = plane
        light = np.full((h, w), ambient, np.float32)
        for s in lights:
            d2 = ((pos - np.array(s.centre, np.float32)) ** 2).sum(-1)
            light += s.power * np.exp(-d2 / (2 * s.radius_m**2))
        return albedo * light

    def _pack(self, tiles) -> np.ndarray:
        """Shelf-pack the face tiles into one float32 atlas, with padding against bleeding."""
        x = y = shelf_h = 0
        placed = []
        for f, tile in tiles:
            h, w = tile.shape
            if x + w + 2 * PAD > ATLAS_WIDTH:
                x, y, shelf_h = 0, y + shelf_h, 0
            placed.append((f, tile, x + PAD, y + PAD))
            x += w + 2 * PAD
            shelf_h = max(shelf_h, h + 2 * PAD)
        atlas = np.zeros((y + shelf_h, ATLAS_WIDTH), np.float32)
        for f, tile, ox, oy in placed:
            h, w = tile.shape
            atlas[oy - PAD : oy + h + PAD, ox - PAD : ox + w + PAD] = cv2.copyMakeBorder(
                tile, PAD, PAD, PAD, PAD, cv2.BORDER_REPLICATE
            )
            self.face_offset[f] = (ox, oy)
        return atlas

    def render(self, R_w_c: np.ndarray, p_w_c: np.ndarray, rays_c: np.ndarray, shape) -> np.ndarray:
        """Radiance seen along camera rays `rays_c` (H*W, 3) from pose (R_w_c, p_w_c [m]); (H, W) float32."""
        out = np.empty(len(rays_c), np.float32)
        _ray_cast(
            np.asarray(R_w_c, np.float32),
            np.asarray(p_w_c, np.float32),
            rays_c,
            self.lo,
            self.hi,
            np.array([b.inside for b in self.boxes]),
            self.face_uv_axes,
            self.face_uv_lo,
            self.face_offset,
            self.face_size,
            self.atlas,
            np.float32(TEXELS_PER_M),
            out,
        )
        return out.reshape(shape)


@numba.njit(cache=True, fastmath=True, parallel=True, nogil=True)
def _ray_cast(R, o, rays, lo, hi, inside, uv_axes, uv_lo, offset, size, atlas, texels_per_m, out):
    """For each ray: nearest box face hit (slab method), then a bilinear atlas lookup."""
    for n in numba.prange(rays.shape[0]):
        r = np.empty(3, np.float32)
        for i in range(3):
            r[i] = R[i, 0] * rays[n, 0] + R[i, 1] * rays[n, 1] + R[i, 2] * rays[n, 2]
        best_t = np.inf
        best_face = 0
        for b in range(lo.shape[0]):
            t_enter, t_exit = -np.inf, np.inf
            ax_enter, ax_exit = 0, 0
            for i in range(3):
                inv = 1.0 / r[i] if abs(r[i]) > 1e-9 else 1e9
                t1 = (lo[b, i] - o[i]) * inv
                t2 = (hi[b, i] - o[i]) * inv
                t_near, t_far = min(t1, t2), max(t1, t2)
                if t_near > t_enter:
                    t_enter, ax_enter = t_near, i
                if t_far < t_exit:
                    t_exit, ax_exit = t_far, i
            if inside[b]:
                t_hit, face = t_exit, b * 6 + ax_exit * 2 + (1 if r[ax_exit] > 0 else 0)
            elif t_enter <= t_exit and t_enter > 1e-4:
                t_hit, face = t_enter, b * 6 + ax_enter * 2 + (1 if r[ax_enter] < 0 else 0)
            else:
                continue
            if t_hit < best_t:
                best_t, best_face = t_hit, face
        ua, va = uv_axes[best_face, 0], uv_axes[best_face, 1]
        u = (o[ua] + best_t * r[ua] - uv_lo[best_face, 0]) * texels_per_m - 0.5
        v = (o[va] + best_t * r[va] - uv_lo[best_face, 1]) * texels_per_m - 0.5
        u = min(max(u, 0.0), size[best_face, 0] - 1.0) + offset[best_face, 0]
        v = min(max(v, 0.0), size[best_face, 1] - 1.0) + offset[best_face, 1]
        x0, y0 = int(u), int(v)
        fx, fy = u - x0, v - y0
        out[n] = (1 - fy) * ((1 - fx) * atlas[y0, x0] + fx * atlas[y0, x0 + 1]) + fy * (
            (1 - fx) * atlas[y0 + 1, x0] + fx * atlas[y0 + 1, x0 + 1]
        )
