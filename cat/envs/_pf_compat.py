"""TEMPORARY: stand-ins until cat.fields exports FieldCfg / humanoid_pf / vmf_log_likelihood."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch


@dataclass
class FieldCfg:
    eta: float = 1.0
    xi: float = 0.02
    d0: float = 0.3
    lam: float = 1.0
    kappa_max: float = 5.0


def humanoid_pf(force, grad_d, d, v, w0, lam):
    w1 = lam * torch.clamp(-(grad_d * v).sum(-1), min=0.5) * torch.exp(-d)
    return (w0 * w1).unsqueeze(-1) * force / force.norm(dim=-1, keepdim=True).clamp_min(1e-9)


def log_c3(kappa):
    k = kappa.clamp_min(1e-6)
    big = torch.log(k) - math.log(2 * math.pi) - k - torch.log1p(-torch.exp(-2 * k))
    small = -math.log(4 * math.pi) - k.square() / 6
    return torch.where(k < 1e-3, small, big)


def vmf_log_likelihood(mu, kappa, v_hat):
    return log_c3(kappa) + kappa * (mu * v_hat).sum(-1)
