"""Numba kernels of the corridor renderer: ray casting, procedural textures, lighting.

Private: no validation, preallocated outputs. Scene arrays come from
``Scene.packed()``; see world/scene.py for their layout.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

_EPS = 1e-9
_MASK = 0xFFFFFFFF


@njit(nogil=True, cache=True, inline="always")
def _hash01(ix, iy, seed):
    """Integer lattice hash -> [0, 1]."""
    h = (ix * 374761393 + iy * 668265263 + seed * 1442695041) & _MASK
    h = ((h ^ (h >> 13)) * 1274126177) & _MASK
    h = h ^ (h >> 16)
    return h / 4294967295.0


@njit(nogil=True, cache=True, inline="always")
def _value_noise(u, v, seed):
    """Smooth value noise in [0, 1] with unit lattice spacing."""
    fu = math.floor(u)
    fv = math.floor(v)
    iu = np.int64(fu)
    iv = np.int64(fv)
    a = u - fu
    b = v - fv
    a = a * a * (3.0 - 2.0 * a)
    b = b * b * (3.0 - 2.0 * b)
    n00 = _hash01(iu, iv, seed)
    n10 = _hash01(iu + 1, iv, seed)
    n01 = _hash01(iu, iv + 1, seed)
    n11 = _hash01(iu + 1, iv + 1, seed)
    return (n00 * (1.0 - a) + n10 * a) * (1.0 - b) + (n01 * (1.0 - a) + n11 * a) * b


@njit(nogil=True, cache=True)
def _fbm(u, v, seed, octaves):
    """Fractal sum of value noise, normalized to [0, 1]."""
    total = 0.0
    amp = 1.0
    norm = 0.0
    freq = 1.0
    for k in range(octaves):
        total += amp * _value_noise(u * freq + 17.3 * k, v * freq - 9.1 * k, seed + 101 * k)
        norm += amp
        amp *= 0.5
        freq *= 2.0
    return total / norm


@njit(nogil=True, cache=True)
def _albedo(mat, u, v, seed):
    """Albedo of material row ``mat`` (kind, albedo, contrast, scale_m, period_m) at (u, v) metres."""
    kind = int(mat[0])
    base = mat[1]
    contrast = mat[2]
    s = mat[3]
    period = mat[4]
    if kind == 0:      # weak: low-contrast smooth noise
        return base + contrast * 2.0 * (_fbm(u / s, v / s, seed, 3) - 0.5)
    if kind == 1:      # tiles: weak noise plus faint grout lines
        a = base + contrast * 2.0 * (_fbm(u / s, v / s, seed, 3) - 0.5)
        fu = u / period - math.floor(u / period)
        fv = v / period - math.floor(v / period)
        if fu < 0.012 or fv < 0.012:
            a -= 1.5 * contrast
        return a
    if kind == 2:      # blotch: strong, sharp-edged multi-scale noise
        n = _fbm(u / s, v / s, seed, 4)
        return base + contrast * math.tanh(6.0 * (n - 0.5))
    if kind == 3:      # checker with noise
        cu = math.floor(u / period)
        cv = math.floor(v / period)
        sign = 1.0 if (np.int64(cu + cv) & 1) == 0 else -1.0
        return base + contrast * (0.7 * sign + 0.6 * (_fbm(u / s, v / s, seed, 2) - 0.5))
    if kind == 4:      # poster: high-contrast fine noise inside a dark frame
        n = _fbm(u / s, v / s, seed, 4)
        m = _value_noise(u / (4.0 * s), v / (4.0 * s), seed + 7)
        return base + contrast * math.tanh(4.0 * (n - 0.5)) + 0.25 * (m - 0.5)
    if kind == 6 or kind == 7:   # stripes across u (6) or v (7), sharp-edged, with weak noise
        w = u if kind == 6 else v
        f = w / period - math.floor(w / period)
        sign = 1.0 if f < 0.5 else -1.0
        return base + contrast * (0.8 * sign + 0.4 * (_fbm(u / s, v / s, seed, 2) - 0.5))
    # kind 5, wood: vertical planks with grain
    plank = math.floor(u / period)
    grain = _value_noise(u / (0.2 * s), v / (6.0 * s) + 13.0 * plank, seed)
    shade = _hash01(np.int64(plank), 3, seed) - 0.5
    fu = u / period - plank
    a = base + contrast * (0.8 * (grain - 0.5) + 0.5 * shade)
    if fu < 0.04:
        a -= contrast
    return a


@njit(nogil=True, cache=True, inline="always")
def _safe_inv(x):
    if abs(x) > 1e-15:
        return 1.0 / x
    return 1e15 if x >= 0.0 else -1e15


@njit(nogil=True, cache=True, inline="always")
def _slab(lo, hi, o, inv, t_near, t_far):
    t1 = (lo - o) * inv
    t2 = (hi - o) * inv
    if t1 > t2:
        t1, t2 = t2, t1
    return max(t_near, t1), min(t_far, t2), t1


@njit(nogil=True, cache=True)
def _trace(ox, oy, oz, dx, dy, dz, boxes, cylinders):
    """Nearest hit: returns (t, kind 0 box / 1 cylinder side / 2 cylinder cap / -1 none, index, axis, sign)."""
    best_t = np.inf
    kind = -1
    index = -1
    axis = 0
    sign = 0.0
    ix = _safe_inv(dx)
    iy = _safe_inv(dy)
    iz = _safe_inv(dz)
    for b in range(boxes.shape[0]):
        t_near, t_far, tx = _slab(boxes[b, 0], boxes[b, 3], ox, ix, -np.inf, np.inf)
        t_near, t_far, ty = _slab(boxes[b, 1], boxes[b, 4], oy, iy, t_near, t_far)
        if t_near > t_far or t_far <= _EPS:
            continue
        t_near, t_far, tz = _slab(boxes[b, 2], boxes[b, 5], oz, iz, t_near, t_far)
        if t_near <= t_far and t_near > _EPS and t_near < best_t:
            best_t = t_near
            kind = 0
            index = b
            if t_near == tx:
                axis = 0
                sign = -1.0 if dx > 0 else 1.0
            elif t_near == ty:
                axis = 1
                sign = -1.0 if dy > 0 else 1.0
            else:
                axis = 2
                sign = -1.0 if dz > 0 else 1.0
    for c in range(cylinders.shape[0]):
        cx = cylinders[c, 0]
        cy = cylinders[c, 1]
        r = cylinders[c, 2]
        h = cylinders[c, 3]
        px = ox - cx
        py = oy - cy
        a = dx * dx + dy * dy
        if a > 1e-18:
            bq = px * dx + py * dy
            cq = px * px + py * py - r * r
            disc = bq * bq - a * cq
            if disc >= 0.0:
                t = (-bq - math.sqrt(disc)) / a
                if t > _EPS and t < best_t:
                    z = oz + t * dz
                    if 0.0 <= z <= h:
                        best_t = t
                        kind = 1
                        index = c
        if abs(dz) > 1e-15:
            t = (h - oz) / dz
            if t > _EPS and t < best_t:
                qx = px + t * dx
                qy = py + t * dy
                if qx * qx + qy * qy <= r * r:
                    best_t = t
                    kind = 2
                    index = c
    return best_t, kind, index, axis, sign


@njit(nogil=True, cache=True)
def _surface(ox, oy, oz, dx, dy, dz, boxes, box_mat, box_label, cylinders, cyl_mat, cyl_label,
             decals, decal_mat, decal_label, materials, skirting_m, skirting_mat, seed):
    """Hit of one ray: (albedo, t, label, point xyz, normal xyz, primitive id); t = inf on a miss."""
    t, kind, index, axis, sign = _trace(ox, oy, oz, dx, dy, dz, boxes, cylinders)
    if kind < 0:
        return 0.0, np.inf, 0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, -1
    px = ox + t * dx
    py = oy + t * dy
    pz = oz + t * dz
    nx = 0.0
    ny = 0.0
    nz = 0.0
    if kind == 0:
        mat = box_mat[index]
        label = box_label[index]
        if axis == 0:
            nx = sign
            u = py
            v = pz
        elif axis == 1:
            ny = sign
            u = px
            v = pz
        else:
            nz = sign
            u = px
            v = py
        if label == 2:   # wall: decals, then the skirting board
            painted = False
            if axis == 1:
                for k in range(decals.shape[0]):
                    if (decals[k, 0] == sign and abs(py - decals[k, 1]) < 1e-6
                            and decals[k, 2] <= px <= decals[k, 3] and decals[k, 4] <= pz <= decals[k, 5]):
                        mat = decal_mat[k]
                        label = decal_label[k]
                        painted = True
                        break
            if not painted and pz < skirting_m and axis != 2:
                mat = skirting_mat
                label = 6
    else:
        mat = cyl_mat[index]
        label = cyl_label[index]
        ex = px - cylinders[index, 0]
        ey = py - cylinders[index, 1]
        if kind == 1:
            r = math.sqrt(ex * ex + ey * ey)
            nx = ex / r
            ny = ey / r
            u = math.atan2(ey, ex) * cylinders[index, 2]
            v = pz
        else:
            nz = 1.0
            u = ex
            v = ey
    albedo = _albedo(materials[mat], u, v, seed * 1009 + 31 * mat)
    albedo = min(max(albedo, 0.02), 1.0)
    prim = 4 * (index * 3 + kind) + axis + (1 if sign > 0 else 0) * 1000003
    return albedo, t, label, px, py, pz, nx, ny, nz, prim


@njit(nogil=True, cache=True)
def _irradiance(px, py, pz, nx, ny, nz, lights, ambient):
    """Ambient plus Lambertian point lights with inverse-square falloff ``P cos / (1 + r^2)``."""
    light = ambient
    for k in range(lights.shape[0]):
        lx = lights[k, 0] - px
        ly = lights[k, 1] - py
        lz = lights[k, 2] - pz
        dist2 = lx * lx + ly * ly + lz * lz
        cos = (nx * lx + ny * ly + nz * lz) / math.sqrt(dist2)
        if cos > 0.0:
            light += lights[k, 3] * cos / (1.0 + dist2)
    return light


@njit(nogil=True, cache=True, parallel=True)
def render_rays(dirs_cam, R_world_from_cam, origin, boxes, box_mat, box_label, cylinders, cyl_mat,
                cyl_label, decals, decal_mat, decal_label, materials, lights, skirting_m, skirting_mat,
                ambient, seed, out_radiance, out_depth, out_label):
    """Render a pixel grid.

    ``dirs_cam`` (H, W, S, 3): S sample rays per pixel in the camera frame;
    the radiance is their mean (lighting evaluated once per pixel and surface).
    ``out_depth`` gets the camera-frame z of the
    first sample's hit (NaN on a miss), ``out_label`` its surface label.
    """
    H, W, S = dirs_cam.shape[0], dirs_cam.shape[1], dirs_cam.shape[2]
    R = R_world_from_cam
    for i in prange(H):
        for j in range(W):
            acc = 0.0
            last_prim = -2
            light = 0.0
            for s in range(S):
                cx = dirs_cam[i, j, s, 0]
                cy = dirs_cam[i, j, s, 1]
                cz = dirs_cam[i, j, s, 2]
                dx = R[0, 0] * cx + R[0, 1] * cy + R[0, 2] * cz
                dy = R[1, 0] * cx + R[1, 1] * cy + R[1, 2] * cz
                dz = R[2, 0] * cx + R[2, 1] * cy + R[2, 2] * cz
                albedo, t, label, px, py, pz, nx, ny, nz, prim = _surface(
                    origin[0], origin[1], origin[2], dx, dy, dz, boxes, box_mat, box_label, cylinders,
                    cyl_mat, cyl_label, decals, decal_mat, decal_label, materials, skirting_m,
                    skirting_mat, seed)
                if prim != last_prim:   # lighting is smooth: once per surface per pixel
                    light = _irradiance(px, py, pz, nx, ny, nz, lights, ambient) if prim >= 0 else 0.0
                    last_prim = prim
                acc += albedo * light
                if s == 0:
                    out_depth[i, j] = t * cz if t < np.inf else np.nan
                    out_label[i, j] = label
            out_radiance[i, j] = acc / S
