"""vMF log-likelihood and reward against scipy, including extreme concentrations."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from scipy import stats

from cat.fields import field_reward, log_c3, vmf_log_likelihood


def _unit(x):
    return x / np.linalg.norm(x, axis=-1, keepdims=True)


@pytest.mark.parametrize("kappa", [1e-9, 1e-6, 1e-4, 1e-3, 0.01, 0.3, 1.0, 7.5, 50.0, 500.0, 2000.0])
def test_vmf_matches_scipy(kappa):
    rng = np.random.default_rng(int(kappa * 1000) % 97)
    mu = _unit(rng.normal(size=(20, 3)))
    v = _unit(rng.normal(size=(20, 3)))
    v[0] = mu[0]
    ref = np.array([stats.vonmises_fisher(mu[i], kappa).logpdf(v[i]) for i in range(20)])
    for dtype, tol in ((torch.float64, 1e-9), (torch.float32, 1e-4)):
        got = vmf_log_likelihood(
            torch.tensor(mu, dtype=dtype), torch.full((20,), kappa, dtype=dtype), torch.tensor(v, dtype=dtype)
        )
        assert torch.isfinite(got).all()
        assert np.allclose(got.double().numpy(), ref, rtol=tol, atol=tol * max(1.0, kappa))


def test_log_c3_limits_and_no_overflow():
    k = torch.tensor([0.0, 1e-30, 1e-3 - 1e-9, 1e-3 + 1e-9, 1e4, 1e6, 1e30], dtype=torch.float32)
    out = log_c3(k)
    assert torch.isfinite(out).all()
    assert out[0].item() == pytest.approx(-math.log(4 * math.pi))
    assert abs(out[2].item() - out[3].item()) < 1e-6  # the two branches join continuously
    assert out[4].item() == pytest.approx(math.log(1e4) - math.log(2 * math.pi) - 1e4, rel=1e-6)
    k64 = torch.linspace(0, 40, 4001, dtype=torch.float64)
    ref = torch.log(k64[1:] / (4 * math.pi * torch.sinh(k64[1:])))
    assert torch.allclose(log_c3(k64[1:]), ref, atol=1e-12)


def test_field_reward_sums_links():
    rng = np.random.default_rng(1)
    F_H = torch.tensor(rng.normal(size=(4, 13, 3)) * 0.3)
    v = torch.tensor(rng.normal(size=(4, 13, 3)))
    r = field_reward(F_H, v, kappa_max=10.0)
    kappa = (10.0 * F_H.norm(dim=-1)).numpy()
    mu = _unit(F_H.numpy())
    vh = _unit(v.numpy())
    ref = np.zeros(4)
    for e in range(4):
        for k in range(13):
            ref[e] += stats.vonmises_fisher(mu[e, k], kappa[e, k]).logpdf(vh[e, k])
    assert np.allclose(r.numpy(), ref, atol=1e-8)
    # alignment is rewarded; a zero field gives the uniform density; a link at rest gets log C3(κ)
    assert field_reward(F_H, F_H).mean() > field_reward(F_H, -F_H).mean()
    zero = field_reward(torch.zeros(1, 13, 3), v[:1])
    assert zero.item() == pytest.approx(-13 * math.log(4 * math.pi))
    rest = field_reward(F_H[:1], torch.zeros(1, 13, 3), per_link=True)
    assert torch.allclose(rest, log_c3(10.0 * F_H[:1].norm(dim=-1)))
