"""Difficulty curriculum over a scene set (paper §III-B): each env climbs through difficulty levels.

Scenes carry a difficulty in [0, 1] (typical variants and procedural scenes both do); ``num_levels`` equal bins of
it are the levels. Training-only warm-up scenes (``EnvCfg.warmup_variants``) have difficulties in [−1, 0); with
them the bins span [−1, 1], so the lowest levels hold the warm-up scenes. Each env has a level; at reset it draws
one of the scenes of its level (or of the nearest lower level that has scenes). After an episode the level goes up
on success and down on failure, so every env settles where it succeeds about half the time and moves on as the
policy improves.

Within a level, scenes are drawn uniformly, or with ``CurriculumCfg.group_weights`` by scene group (a scene's
kind: a typical type, ``indoor``, ``procedural``): each group present at the level gets a share of the draws in
proportion to its weight (unnamed groups weigh 1), uniform among its scenes there. A mixed set keeps a group's
share whatever its scene count: 50 typical scenes beside 269 hybrid ones are 16 % of uniform draws, and a
generalist trained on them forgets the typical skills (docs/results.md).
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

import torch


@dataclass
class CurriculumCfg:
    enabled: bool = True  # False: env i always trains in scene i % num_scenes
    num_levels: int = 5  # equal-width bins of scene difficulty in [0, 1] ([-1, 1] with warm-up scenes)
    start_level: int = 0  # level of every env at the start of training
    group_weights: dict[str, float] = field(default_factory=dict)
    """Scene group -> its relative share of the draws within a level (unnamed groups: 1); empty: uniform over
    scenes."""


class DifficultyCurriculum:
    """Per-env difficulty level, promoted after a success and demoted after a failure."""

    def __init__(
        self,
        difficulties: torch.Tensor,
        num_envs: int,
        cfg: CurriculumCfg,
        groups: list[str] | None = None,
    ):
        """``groups``: each scene's group (kind), needed with ``cfg.group_weights``."""
        if cfg.num_levels < 1:
            raise ValueError(f"curriculum.num_levels must be >= 1, got {cfg.num_levels}")
        d = difficulties.detach().cpu().float().clamp(-1.0, 1.0)
        lo = -1.0 if bool((d < 0).any()) else 0.0
        self.scene_level = torch.clamp(((d - lo) / (1.0 - lo) * cfg.num_levels).long(), 0, cfg.num_levels - 1)
        self.num_levels = cfg.num_levels
        present = torch.zeros(cfg.num_levels, dtype=torch.bool)
        present[self.scene_level] = True
        # level -> the level whose scenes it draws from: itself, else the nearest lower one with scenes
        lowest = int(self.scene_level.min())
        self._source = torch.empty(cfg.num_levels, dtype=torch.long)
        last = lowest
        for lvl in range(cfg.num_levels):
            last = lvl if present[lvl] else last
            self._source[lvl] = last
        self.max_level = int(self.scene_level.max())
        # with warm-up scenes: the lowest level holding a scene of the paper's range (d >= 0)
        paper = self.scene_level[d >= 0]
        self.first_paper_level = int(paper.min()) if lo < 0 and len(paper) else None
        start = min(max(cfg.start_level, 0), self.max_level)
        self.level = torch.full((num_envs,), start, dtype=torch.long)
        self.scene_weight = self._scene_weights(cfg.group_weights, groups) if cfg.group_weights else None

    def _scene_weights(self, weights: dict[str, float], groups: list[str] | None) -> torch.Tensor:
        """(S,) draw weight of each scene: its group's weight over the group's scene count at the scene's level."""
        if groups is None or len(groups) != len(self.scene_level):
            raise ValueError("curriculum.group_weights needs each scene's group")
        unknown = sorted(set(weights) - set(groups))
        if unknown:
            raise ValueError(
                f"curriculum.group_weights names {unknown}, not a scene group of this set; groups: "
                f"{', '.join(dict.fromkeys(groups))}"
            )
        bad = {g: w for g, w in weights.items() if not (float(w) > 0 and math.isfinite(float(w)))}
        if bad:
            raise ValueError(f"curriculum.group_weights must be finite and > 0, got {bad}")
        keys = list(zip(groups, self.scene_level.tolist(), strict=True))
        count = Counter(keys)
        return torch.tensor([float(weights.get(g, 1.0)) / count[(g, lvl)] for g, lvl in keys], dtype=torch.float64)

    def update(self, env_ids: torch.Tensor, success: torch.Tensor) -> None:
        """Promote ``env_ids`` whose episode succeeded, demote the others."""
        ids = env_ids.cpu()
        step = torch.where(success.cpu(), 1, -1)
        self.level[ids] = (self.level[ids] + step).clamp(0, self.max_level)

    def pick_scenes(self, env_ids: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        """One scene index per env among the scenes of its (source) level: uniformly, or by group weight."""
        src = self._source[self.level[env_ids.cpu()]]
        out = torch.empty(len(src), dtype=torch.long)
        for lvl in src.unique().tolist():
            rows = (src == lvl).nonzero(as_tuple=False).flatten()
            pool = (self.scene_level == lvl).nonzero(as_tuple=False).flatten()
            if self.scene_weight is None:
                out[rows] = pool[torch.randint(len(pool), (len(rows),), generator=gen)]
            else:
                pick = torch.multinomial(self.scene_weight[pool], len(rows), replacement=True, generator=gen)
                out[rows] = pool[pick]
        return out

    def progress(self, env_ids: torch.Tensor) -> torch.Tensor:
        """(k,) each env's place in the curriculum, (level + 1) / (max_level + 1) in (0, 1]."""
        return (self.level[env_ids.cpu()].float() + 1.0) / (self.max_level + 1.0)

    def mean_level(self) -> float:
        return float(self.level.float().mean())

    def log(self) -> dict[str, float]:
        """``Curriculum/mean_level``; with warm-up scenes also ``Curriculum/paper_range``, the fraction of envs at a
        level of the paper's difficulty range (past the warm-ups)."""
        out = {"Curriculum/mean_level": self.mean_level()}
        if self.first_paper_level is not None:
            out["Curriculum/paper_range"] = float((self.level >= self.first_paper_level).float().mean())
        return out

    def state_dict(self) -> dict:
        return {"level": self.level.clone()}

    def load_state_dict(self, state: dict) -> None:
        level = state["level"]
        if level.shape != self.level.shape:
            raise ValueError(
                f"curriculum state for {level.shape[0]} envs cannot resume a run of {len(self.level)} envs"
            )
        self.level = level.clone().clamp(0, self.max_level)
