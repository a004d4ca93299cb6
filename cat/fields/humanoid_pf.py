"""HumanoidPF at the links and its vMF reward, as plain vectorised torch functions (paper §III-A).

Shapes: N envs × K links; vectors (N, K, 3), scalars (N, K). The env calls these every step.
"""

from __future__ import annotations

import math

import torch

_LOG_4PI = math.log(4.0 * math.pi)
_LOG2 = math.log(2.0)


def priority_weights(
    grad_d: torch.Tensor,
    d: torch.Tensor,
    v: torch.Tensor,
    lam: float = 1.0,
    root_index: int = 0,
    w_root: float = 1.0,
    w_other: float = 0.5,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Priority weights: w0 (K,) = 1 for the root, 0.5 otherwise; w1 (N, K) = λ·max(−∇d·v, 0.5)·exp(−d).

    d is clamped at 0 inside the exponential so w1 stays bounded for links inside obstacles."""
    k = grad_d.shape[-2]
    w0 = torch.full((k,), w_other, dtype=grad_d.dtype, device=grad_d.device)
    w0[root_index] = w_root
    approach = -(grad_d * v).sum(-1)
    w1 = lam * approach.clamp(min=0.5) * torch.exp(-d.clamp(min=0.0))
    return w0, w1


def humanoid_pf(
    F: torch.Tensor,
    grad_d: torch.Tensor,
    d: torch.Tensor,
    v: torch.Tensor,
    w0: torch.Tensor | None = None,
    lam: float = 1.0,
    root_index: int = 0,
    eps: float = 1e-9,
) -> torch.Tensor:
    """F_H = w0·w1·F/‖F‖ (N, K, 3); zero where ‖F‖ < eps (the goal itself)."""
    w0_default, w1 = priority_weights(grad_d, d, v, lam, root_index)
    w0 = w0_default if w0 is None else w0.to(F)
    norm = torch.linalg.vector_norm(F, dim=-1)
    scale = torch.where(norm > eps, (w0 * w1) / norm.clamp(min=eps), 0.0)
    return F * scale.unsqueeze(-1)


def log_c3(kappa: torch.Tensor) -> torch.Tensor:
    """log C_3(κ) = log(κ / (4π sinh κ)), stable for κ → 0 (→ −log 4π) and κ ≫ 1 (no overflow).

    Uses log(κ/sinh κ) = log 2κ − κ − log(1 − e^{−2κ}) and the series −κ²/6 + κ⁴/180 for κ < 1e-3."""
    k = kappa.clamp(min=0.0)
    small = k < 1e-3
    ks = torch.where(small, torch.ones_like(k), k)
    large = torch.log(2.0 * ks) - ks - torch.log(-torch.expm1(-2.0 * ks))
    k2 = k * k
    series = -k2 / 6.0 + k2 * k2 / 180.0
    return torch.where(small, series, large) - _LOG_4PI


def vmf_log_likelihood(mu: torch.Tensor, kappa: torch.Tensor, v_hat: torch.Tensor) -> torch.Tensor:
    """log p(v̂ | μ, κ) of the 3-D von Mises–Fisher distribution: log C_3(κ) + κ μᵀv̂."""
    return log_c3(kappa) + kappa * (mu * v_hat).sum(-1)


def field_reward(
    F_H: torch.Tensor,
    v: torch.Tensor,
    kappa_max: float = 10.0,
    kappa_cap: float = 100.0,
    eps: float = 1e-6,
    per_link: bool = False,
) -> torch.Tensor:
    """R_field = Σ_k [log C_3(κ_k) + κ_k μ_kᵀ v̂_k] with μ = F_H/‖F_H‖, κ = min(κ_max‖F_H‖, κ_cap).

    A link at rest (‖v‖ < eps) has v̂ = 0 and contributes log C_3(κ) (no direction preferred by it);
    a link with F_H = 0 has κ = 0 and contributes the uniform density −log 4π."""
    fn = torch.linalg.vector_norm(F_H, dim=-1)
    vn = torch.linalg.vector_norm(v, dim=-1)
    kappa = (kappa_max * fn).clamp(max=kappa_cap)
    # κ μᵀv̂ = κ (F_H·v) / (‖F_H‖‖v‖), zero when either vector vanishes
    denom = fn * vn
    ok = (fn > eps) & (vn > eps)
    cos = torch.where(ok, (F_H * v).sum(-1) / denom.clamp(min=eps * eps), 0.0)
    ll = log_c3(kappa) + kappa * cos
    return ll if per_link else ll.sum(-1)
