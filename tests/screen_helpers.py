"""What tests of images share: which pixel centres lie far from every projected edge (where a soft or
antialiased image must equal the hard one)."""
import torch

from course.soft import _screen_faces


def far_from_edges(mesh, camera, px=1.0):
    """(H, W) bool: pixel centres farther than ``px`` pixels from every projected edge of a front face."""
    with torch.no_grad():
        xy, _, _, _ = _screen_faces(mesh.verts.double(), mesh.faces, camera, True)
    H, W = camera.height, camera.width
    yy, xx = torch.meshgrid(torch.arange(H, dtype=torch.float64) + 0.5, torch.arange(W, dtype=torch.float64) + 0.5,
                            indexing="ij")
    p = torch.stack([xx.reshape(-1), yy.reshape(-1)], 1)                    # (P, 2)
    best = torch.full((p.shape[0],), float("inf"), dtype=torch.float64)
    for k in range(3):
        s, e = xy[:, k], xy[:, (k + 1) % 3]                                  # (T, 2)
        d = e - s
        t = (((p[:, None] - s[None]) * d[None]).sum(-1) / (d * d).sum(-1).clamp_min(1e-30)).clamp(0, 1)
        best = torch.minimum(best, (p[:, None] - (s[None] + t[..., None] * d[None])).norm(dim=-1).min(1).values)
    return (best > px).view(H, W)
