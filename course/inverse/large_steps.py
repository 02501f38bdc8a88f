"""Large steps for mesh optimisation (lecture 10; Nicolet, Jacobson and Jakob, SIGGRAPH Asia 2021).

A gradient with respect to the vertices is local: a silhouette's gradient pushes the few vertices on the
outline, and a plain step moves them alone, so a fit grows spikes and folds long before the surface as a whole
has moved. Nicolet et al. change the variables instead of adding a regulariser: optimise

    u = (I + λ L) v          (v: the vertex positions, L: the mesh's Laplacian, λ > 0)

and recover v = (I + λ L)⁻¹ u after every step. The gradient with respect to u is (I + λ L)⁻¹ times the
gradient with respect to v: a smoothed gradient, so one step moves whole regions of the surface, and with the
Adam variant below, a step of the same size everywhere. λ sets how far a vertex's gradient spreads: with the
combinatorial Laplacian it reaches a few times √λ edges.

* ``laplacian(faces, n)``: the uniform (combinatorial) Laplacian L = D - A, dense (n, n): D the degrees, A the
  adjacency of the mesh's edges.
* ``Parameterization(verts, faces, lam)``: u = M v with M = I + λ L, Cholesky-factored once (``torch.linalg.
  cholesky``); ``.u`` is the leaf to optimise, ``.verts()`` solves M v = u (two triangular solves, which autograd
  differentiates: the gradient reaching u is M⁻¹ times the gradient at v, M being symmetric). Copies of one
  position (a seam: ``boundary._weld``) are one unknown, so the surface cannot open a crack.
* ``UniformAdam``: Adam whose second-moment scale is one number for all entries (their largest), as Nicolet et
  al. use: per-entry scaling would undo the smoothing.

The factorisation is dense: n² numbers (a 2,562-vertex sphere: 52 MB) and n³/3 operations once per mesh, then
two triangular solves a step. That is fine up to a few thousand vertices, which is where this course fits
meshes; Nicolet et al. use a sparse Cholesky (CHOLMOD) for millions.
"""
from __future__ import annotations

import torch

__all__ = ["laplacian", "Parameterization", "UniformAdam"]

MAX_VERTICES = 8000      # dense factor: 8000² float64 = 512 MB


def laplacian(faces, n: int, *, dtype=torch.float64) -> torch.Tensor:
    """(n, n) the uniform Laplacian of the mesh's edges: ``L[i, i]`` the number of neighbours of i, ``L[i, j] = -1``
    for every edge (i, j). Symmetric, positive semi-definite, rows summing to 0."""
    faces = torch.as_tensor(faces).long()
    e = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    e = torch.unique(torch.sort(e, dim=1).values, dim=0)
    e = e[e[:, 0] != e[:, 1]]
    L = torch.zeros(n, n, dtype=dtype)
    L[e[:, 0], e[:, 1]] = -1.0
    L[e[:, 1], e[:, 0]] = -1.0
    L -= torch.diag(L.sum(1))
    return L


class Parameterization:
    """u = (I + λ L) v for the vertices of a mesh (welded positions), Cholesky-factored once."""

    def __init__(self, verts, faces, lam: float = 20.0):
        from ..boundary import _weld
        verts = torch.as_tensor(verts).detach().double()
        faces = torch.as_tensor(faces).long()
        if isinstance(lam, bool) or not isinstance(lam, (int, float)) or not lam >= 0:
            raise ValueError(f"lam must be a number >= 0, got {lam!r}")
        self.weld = _weld(verts)                                            # (V,) one id per position
        n = int(self.weld.max()) + 1
        if n > MAX_VERTICES:
            raise ValueError(f"{n} vertex positions: the dense factor of (I + λL) would need {n * n * 8 / 2**30:.1f} "
                             f"GB; Parameterization takes at most {MAX_VERTICES}")
        first = torch.full((n,), verts.shape[0], dtype=torch.long).scatter_reduce(
            0, self.weld, torch.arange(verts.shape[0]), "amin")
        self.lam = float(lam)
        self.M = torch.eye(n, dtype=torch.float64) + self.lam * laplacian(self.weld[faces], n)
        self.factor = torch.linalg.cholesky(self.M)
        self.u = (self.M @ verts[first]).requires_grad_(True)               # the leaf to optimise

    def verts(self) -> torch.Tensor:
        """(V, 3) the vertex positions of the current u: solve (I + λL) v = u; differentiable in u.

        The two triangular solves with the factor C (C Cᵀ = I + λL: C y = u, then Cᵀ v = y) are what
        ``torch.cholesky_solve`` does, bit for bit, forward and backward, in a sixth of the time on one CPU
        thread for a few thousand vertices (LAPACK's potrs against two blocked trsm calls)."""
        y = torch.linalg.solve_triangular(self.factor, self.u, upper=False)
        return torch.linalg.solve_triangular(self.factor.mT, y, upper=True)[self.weld]


class UniformAdam(torch.optim.Optimizer):
    """Adam with one second-moment scale for every entry: the step is ``lr · m̂ / √(max v̂)`` (β₁ = 0.9,
    β₂ = 0.999, bias-corrected), so the smoothing of the parameterization survives the step."""

    def __init__(self, params, lr: float = 1e-2, betas=(0.9, 0.999), eps: float = 1e-8):
        super().__init__(params, dict(lr=lr, betas=betas, eps=eps))

    @torch.no_grad()
    def step(self, closure=None):
        loss = closure() if closure is not None else None
        for group in self.param_groups:
            b1, b2 = group["betas"]
            for p in group["params"]:
                if p.grad is None:
                    continue
                state = self.state[p]
                if not state:
                    state["step"], state["m"], state["v"] = 0, torch.zeros_like(p), torch.zeros_like(p)
                state["step"] += 1
                m, v, t = state["m"], state["v"], state["step"]
                m.mul_(b1).add_(p.grad, alpha=1 - b1)
                v.mul_(b2).addcmul_(p.grad, p.grad, value=1 - b2)
                scale = (v.max() / (1 - b2 ** t)).sqrt() + group["eps"]
                p.add_(m / (1 - b1 ** t) / scale, alpha=-group["lr"])
        return loss
