"""Difficulty curriculum over a scene set (paper §III-B): each env climbs through difficulty levels.

Scenes carry a difficulty in [0, 1] (typical variants and procedural scenes both do); ``num_levels`` equal bins of
it are the levels. Training-only warm-up scenes (``EnvCfg.warmup_variants``) have difficulties in [−1, 0); with
them the bins span [−1, 1], so the lowest levels hold the warm-up scenes. Each env has a level; at reset it draws
one of the scenes of its level (or of the nearest lower level that has scenes). After an episode the level goes up
on success and down on failure, so every env settles where it succeeds about half the time and moves on as the
policy improves.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch


@dataclass
class CurriculumCfg:
    enabled: bool = True  # False: env i always trains in scene i % num_scenes
    num_levels: int = 5  # equal-width bins of scene difficulty in [0, 1] ([-1, 1] with warm-up scenes)
    start_level: int = 0  # level of every env at the start of training


class DifficultyCurriculum:
    """Per-env difficulty level, promoted after a success and demoted after a failure."""

    def __init__(self, difficulties: torch.Tensor, num_envs: int, cfg: CurriculumCfg):
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

    def update(self, env_ids: torch.Tensor, success: torch.Tensor) -> None:
        """Promote ``env_ids`` whose episode succeeded, demote the others."""
        ids = env_ids.cpu()
        step = torch.where(success.cpu(), 1, -1)
        self.level[ids] = (self.level[ids] + step).clamp(0, self.max_level)

    def pick_scenes(self, env_ids: torch.Tensor, gen: torch.Generator) -> torch.Tensor:
        """One scene index per env, uniformly among the scenes of its (source) level."""
        src = self._source[self.level[env_ids.cpu()]]
        out = torch.empty(len(src), dtype=torch.long)
        for lvl in src.unique().tolist():
            rows = (src == lvl).nonzero(as_tuple=False).flatten()
            pool = (self.scene_level == lvl).nonzero(as_tuple=False).flatten()
            out[rows] = pool[torch.randint(len(pool), (len(rows),), generator=gen)]
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
