"""Stage 1 of ``rasterize`` as a compiled loop over the faces (twin of ``raster._screen_triangles``, lecture 03).

For each face: drop it when it lies wholly before the near plane or beyond the far plane, or faces away
(``cull``); note it for clipping when it crosses the near plane; otherwise gather its projected corners,
put them in the order that makes the screen area positive, and keep it when it has area and reaches the
image. The arithmetic is ``raster._screen_triangles``' (the same edge function, the same comparisons, the
back-face test through ``raster._cross`` and ``raster._dot``), so the kept triangles and their coordinates
are bit-identical; the faces that cross the near plane are clipped afterwards by the torch code.
"""
from __future__ import annotations

import numba
import numpy as np

__all__ = ["screen_triangles", "warm_up"]


@numba.njit(cache=True, error_model="numpy")
def screen_triangles(verts_cam, faces, xy_v, q_v, near, far, cull, orthographic, width, height, reach,
                     xy, q, face, crossing):
    """verts_cam (V, 3) float64 camera space; faces (F, 3) int64; xy_v (V, 2), q_v (V,) every vertex
    projected (``raster._project``). Writes the kept whole triangles into xy (F, 3, 2), q (F, 3) and face
    (F,), in face order, and the ids of faces crossing the near plane into crossing (F,). Returns the
    number of each and whether a kept face reaches beyond the far plane."""
    n, n_cross, crosses_far = 0, 0, False
    order = np.empty(3, np.int64)
    for f in range(faces.shape[0]):
        i0, i1, i2 = faces[f, 0], faces[f, 1], faces[f, 2]
        z0, z1, z2 = verts_cam[i0, 2], verts_cam[i1, 2], verts_cam[i2, 2]
        z_min, z_max = min(min(z0, z1), z2), max(max(z0, z1), z2)
        if not (z_max >= near and z_min <= far):
            continue
        if cull:
            e1x, e1y, e1z = verts_cam[i1, 0] - verts_cam[i0, 0], verts_cam[i1, 1] - verts_cam[i0, 1], z1 - z0
            e2x, e2y, e2z = verts_cam[i2, 0] - verts_cam[i0, 0], verts_cam[i2, 1] - verts_cam[i0, 1], z2 - z0
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x   # raster._cross
            if orthographic:
                if not nz < 0:
                    continue
            elif not (nx * verts_cam[i0, 0] + ny * verts_cam[i0, 1]) + nz * z0 < 0:   # raster._dot
                continue
        if z_max > far:
            crosses_far = True
        if not z_min >= near:                                               # crosses the near plane: clip later
            crossing[n_cross] = f
            n_cross += 1
            continue
        ax, ay, bx, by = xy_v[i0, 0], xy_v[i0, 1], xy_v[i1, 0], xy_v[i1, 1]
        px, py = xy_v[i2, 0], xy_v[i2, 1]
        area = (ax - px) * (by - py) - (ay - py) * (bx - px)                # scan.edge_function(v0, v1, v2)
        if area == 0:                                                       # covers nothing
            continue
        order[0], order[1], order[2] = i0, i1, i2
        if area < 0:                                                        # (v0, v1, v2) → (v0, v2, v1)
            order[1], order[2] = i2, i1
        x_min = min(min(xy_v[i0, 0], xy_v[i1, 0]), xy_v[i2, 0])
        x_max = max(max(xy_v[i0, 0], xy_v[i1, 0]), xy_v[i2, 0])
        y_min = min(min(xy_v[i0, 1], xy_v[i1, 1]), xy_v[i2, 1])
        y_max = max(max(xy_v[i0, 1], xy_v[i1, 1]), xy_v[i2, 1])
        if not (x_max >= reach and x_min <= width - reach and y_max >= reach and y_min <= height - reach):
            continue
        for k in range(3):
            xy[n, k, 0], xy[n, k, 1], q[n, k] = xy_v[order[k], 0], xy_v[order[k], 1], q_v[order[k]]
        face[n] = f
        n += 1
    return n, n_cross, crosses_far


def warm_up():
    """Compile ``screen_triangles`` (or load it from the cache)."""
    v = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 1.0]])
    f = np.array([[0, 1, 2]])
    screen_triangles(v, f, v[:, :2].copy(), v[:, 2].copy(), 0.1, 10.0, True, False, 4, 4, 0.5,
                     np.empty((1, 3, 2)), np.empty((1, 3)), np.empty(1, np.int64), np.empty(1, np.int64))
