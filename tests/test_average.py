"""scripts/average.py: interpolating two checkpoints of one lineage (cat/learning/average.py)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from cat.checkpoint_io import CheckpointError
from cat.launcher import load_script
from cat.learning.average import EPS, AverageCfg, average, average_states

REPO = Path(__file__).resolve().parents[1]
V2 = REPO / "checkpoints/generalist_hybrid_v2/model_244.pt"
TYPICAL = REPO / "checkpoints/hybrid_student_typical/generalist/seed0/model_244.pt"


def _forward(state: dict, x: torch.Tensor) -> torch.Tensor:
    """The rsl_rl MLP student's mean action: normaliser, then Linear/ELU layers (``mlp.<k>``)."""
    h = (x - state["obs_normalizer._mean"]) / (state["obs_normalizer._std"] + EPS)
    layers = sorted({int(k.split(".")[1]) for k in state if k.startswith("mlp.")})
    for i, k in enumerate(layers):
        h = h @ state[f"mlp.{k}.weight"].T + state[f"mlp.{k}.bias"]
        if i < len(layers) - 1:
            h = torch.nn.functional.elu(h)
    return h


def _state(seed: int, n_in: int = 6) -> dict:
    g = torch.Generator().manual_seed(seed)
    std = torch.rand(1, n_in, generator=g) * 2 + 0.1
    return {
        "obs_normalizer._mean": torch.randn(1, n_in, generator=g),
        "obs_normalizer._var": std**2,
        "obs_normalizer._std": std,
        "obs_normalizer.count": torch.tensor(100),
        "distribution.std_param": torch.rand(2, generator=g),
        "mlp.0.weight": torch.randn(5, n_in, generator=g),
        "mlp.0.bias": torch.randn(5, generator=g),
        "mlp.2.weight": torch.randn(2, 5, generator=g),
        "mlp.2.bias": torch.randn(2, generator=g),
    }


def test_b_is_re_expressed_exactly_in_a_normaliser():
    """alpha=1 computes b's function with a's normaliser; alpha=0 is a; between them every weight is mixed."""
    a, b = _state(0), _state(1)
    x = torch.randn(64, 6, dtype=torch.float64)
    a64 = {k: v.double() if v.is_floating_point() else v for k, v in a.items()}
    b64 = {k: v.double() if v.is_floating_point() else v for k, v in b.items()}
    at_b = average_states(a64, b64, 1.0)
    assert torch.allclose(_forward(at_b, x), _forward(b64, x), atol=1e-10)
    assert torch.equal(at_b["obs_normalizer._mean"], a64["obs_normalizer._mean"])
    at_a = average_states(a, b, 0.0)
    assert all(torch.equal(at_a[k], a[k]) for k in a)
    mid = average_states(a, b, 0.5)
    assert torch.allclose(mid["mlp.2.weight"], (a["mlp.2.weight"] + b["mlp.2.weight"]) / 2)
    assert not torch.allclose(_forward(mid, x.float()), _forward(a, x.float()))


def test_shapes_that_differ_are_refused_by_name():
    a, b = _state(0), _state(1, n_in=7)
    with pytest.raises(CheckpointError, match=r"obs_normalizer\._mean is \(1, 6\) in a and \(1, 7\) in b"):
        average_states(a, b, 0.5, "student")


def test_script_on_shipped_students(tmp_path, caplog):
    """Two shipped DAgger legs of one lineage: written with a's config and a note, weights only; alpha=1 plays b;
    a checkpoint of another observation layout and a bad alpha are refused with nothing written."""
    out = tmp_path / "soup"
    mod = load_script(REPO / "scripts" / "average.py")
    assert mod.main([f"a={V2}", f"b={TYPICAL}", "alpha=1", f"out={out}"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["average.yaml", "config.yaml", "model_244.pt"]
    mixed = torch.load(out / "model_244.pt", weights_only=True)
    assert "optimizer_state_dict" not in mixed
    b = torch.load(TYPICAL, weights_only=True)["student_state_dict"]
    x = torch.randn(32, b["mlp.0.weight"].shape[1]) * b["obs_normalizer._std"] + b["obs_normalizer._mean"]
    assert torch.allclose(_forward(mixed["student_state_dict"], x), _forward(b, x), atol=1e-4)
    voxel = REPO / "checkpoints/table3/voxel/seed0/model_610.pt"
    assert mod.main([f"a={V2}", f"b={voxel}", f"out={tmp_path / 'bad'}"]) == 2
    assert "different observation layouts" in caplog.text
    with pytest.raises(ValueError, match="alpha must lie in"):
        average(AverageCfg(a=str(V2), b=str(TYPICAL), alpha=1.5, out=str(tmp_path / "bad")))
    assert not (tmp_path / "bad").exists()
    assert mod.main([f"a={V2}", f"b={TYPICAL}", f"out={out}"]) == 2  # out holds a model: force=true needed


def test_a_ppo_fine_tune_and_its_distilled_parent_mix_their_policies(tmp_path, caplog):
    """WiSE-FT: the shipped PPO fine-tune (actor + critic) and the DAgger student it started from (student +
    teachers) mix through their deployable networks only; a's critic-free layout is kept, alpha=1 plays b's actor."""
    parent = REPO / "checkpoints/generalist/model_4505.pt"
    tuned = REPO / "checkpoints/generalist_ft/model_914.pt"
    out = tmp_path / "wise"
    mod = load_script(REPO / "scripts" / "average.py")
    assert mod.main([f"a={parent}", f"b={tuned}", "alpha=1", f"out={out}"]) == 0
    mixed = torch.load(out / "model_4505.pt", weights_only=False)
    assert "student_state_dict" in mixed and "actor_state_dict" not in mixed and "critic_state_dict" not in mixed
    actor = torch.load(tuned, weights_only=True)["actor_state_dict"]
    x = torch.randn(32, actor["mlp.0.weight"].shape[1]) * actor["obs_normalizer._std"] + actor["obs_normalizer._mean"]
    assert torch.allclose(_forward(mixed["student_state_dict"], x), _forward(actor, x), atol=1e-4)
    assert mod.main([f"a={tuned}", f"b={parent}", "alpha=0", f"out={tmp_path / 'back'}"]) == 0
    back = torch.load(tmp_path / "back" / "model_914.pt", weights_only=False)
    assert set(back) >= {"actor_state_dict", "iter"} and "critic_state_dict" not in back
    assert all(torch.equal(back["actor_state_dict"][k], actor[k]) for k in actor)
    voxel = REPO / "checkpoints/table3/voxel/seed0/model_610.pt"  # a PPO run reading another layout
    assert mod.main([f"a={parent}", f"b={voxel}", f"out={tmp_path / 'bad'}"]) == 2
    assert "different observation layouts" in caplog.text
    # the same layout, but a PPO actor that reads other groups than the student: not one policy lineage
    other = tmp_path / "other"
    other.mkdir()
    (other / tuned.name).symlink_to(tuned)
    text = (tuned.parent / "config.yaml").read_text()
    assert "    actor:\n    - student_proprio\n    - student\n" in text
    (other / "config.yaml").write_text(text.replace("    actor:\n    - student_proprio\n", "    actor:\n", 1))
    assert mod.main([f"a={parent}", f"b={other / tuned.name}", f"out={tmp_path / 'bad'}"]) == 2
    assert "not one policy lineage" in caplog.text
    assert not (tmp_path / "bad").exists()
