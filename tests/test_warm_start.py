"""Warm start from a prior: inputs the prior never saw vary are detached, so the new task starts from the prior's
behaviour (not from what its normaliser makes of an unseen SDF)."""

from __future__ import annotations

import torch
from tensordict import TensorDict

from cat.learning.config import AlgoCfg, policy_model
from cat.learning.warm_start import adapt_model, unseen_columns


def _prior(obs: TensorDict):
    model = policy_model(AlgoCfg()).build(obs, 3)
    x = obs["actor"]
    with torch.no_grad():  # the prior's normaliser: columns 0-3 varied, column 4 was constant 1 (+ noise)
        model.obs_normalizer._mean[0] = torch.tensor([0.0, 0.0, 0.0, 0.0, 1.0])
        std = torch.tensor([1.0, 1.0, 1.0, 1.0, 0.03])
        model.obs_normalizer._std[0], model.obs_normalizer._var[0] = std, std.square()
    return model.eval(), x


def test_unseen_columns_are_detached_and_the_prior_behaviour_kept():
    g = torch.Generator().manual_seed(0)
    familiar = torch.randn(64, 4, generator=g)
    seen = TensorDict({"actor": torch.cat((familiar, 1.0 + 0.01 * torch.randn(64, 1, generator=g)), -1)}, [64])
    model, _ = _prior(seen)
    new = seen.clone()
    new["actor"][:, 4] = torch.rand(64, generator=g) * 1.6 - 0.6  # an SDF in a scene: -0.6 .. 1
    assert unseen_columns(model.obs_normalizer._mean[0], model.obs_normalizer._std[0], new["actor"]).tolist() == [
        False, False, False, False, True,
    ]  # fmt: skip
    at_mean = seen.clone()
    at_mean["actor"][:, 4] = 1.0  # the prior's typical reading of the column
    before_on_prior_data = model(at_mean)
    assert (model(new) - before_on_prior_data).abs().max() > 0.2  # far off: 50 normalised units in one column
    assert adapt_model(model, new["actor"]) == 1
    # the new column no longer moves the action; the familiar ones act exactly as before
    torch.testing.assert_close(model(new), model(at_mean))
    torch.testing.assert_close(model(at_mean), before_on_prior_data, atol=1e-6, rtol=0)
    assert abs(float(model.obs_normalizer._mean[0, 4]) - float(new["actor"][:, 4].mean())) < 1e-6
    assert adapt_model(model, new["actor"]) == 0  # now in range: nothing more to do
