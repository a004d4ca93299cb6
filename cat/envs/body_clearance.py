"""Per-body clearance: how far each robot body's collision shapes are from the nearest obstacle (issue 28).

HumanoidPF is queried at 13 link origins, so a toe 14 cm ahead of the ankle origin or a hand's edge is not seen
until it touches, and most of the generalist's unseen-set failures are contacts under 1 cm (docs/results.md, "How
deep the unseen-set contacts go"). The ``body_clearance`` observation term gives a policy that sense: per robot
body with a collision geom, the smallest SDF over its judged shapes, measured as ``sim.obstacles=field`` judges
contact (:class:`cat.envs.field_contact.FieldContact`: capsule axes and sphere centres at SDF − radius, boxes by
surface samples) on each scene's contact SDF (exact within 0.1 m of a surface), clipped to ±``CLEARANCE_CLIP``;
on flat ground (no scene) every body reads +``CLEARANCE_CLIP``.

Body poses come from MuJoCo frame sensors, which every env model that needs them carries:
the field mode's floor-only model always, physical worlds when a group reads ``body_clearance``. A privileged
term for now (a teacher's or a critic's input): the deploy runtime does not compute it from a robot's own map.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import mujoco
import torch

from cat.envs.field_contact import (
    FieldContact,
    FieldContactCfg,
    collision_geom_ids,
    fill_contact_sdf,
    judged_body_ids,
)
from cat.envs.robot import RobotCfg, compile_model, robot_spec

if TYPE_CHECKING:
    from cat.envs.traversal_env import TraversalEnv

TERM = "body_clearance"
CLEARANCE_CLIP = 0.08
"""m: the term reads min(SDF, 0.08) per body (and at least −0.08 inside). Within the contact SDF's exact band
(0.1 m); a body whose bounding sphere is clear by more than this (+ the cull slack) is not queried point by point."""


_BODIES: dict[tuple, tuple[str, ...]] = {}


def clearance_bodies(robot: RobotCfg) -> list[str]:
    """The bodies ``body_clearance`` reads, in its column order (:class:`FieldContact`'s: by first collision geom)."""
    key = (robot.model_entry, tuple(robot.collision_geoms))
    if key not in _BODIES:
        model = compile_model(robot_spec(robot, floor=False))
        _BODIES[key] = tuple(model.body(b).name for b in judged_body_ids(model, collision_geom_ids(model, robot)))
    return list(_BODIES[key])


class BodyClearance:
    """The ``body_clearance`` reading of an env: one fused SDF query over every env's collision bodies."""

    def __init__(self, env: TraversalEnv, model: mujoco.MjModel):
        self.width = len(clearance_bodies(env.robot))
        self.fc: FieldContact | None = None
        if env.scenes is None:  # flat ground: no obstacle anywhere, every body reads clear (+clip)
            return
        # the margin sets the cull distance: a body left out of the point query is farther than the clip
        cfg = FieldContactCfg(margin=CLEARANCE_CLIP, substeps=False)
        self.fc = FieldContact(model, env.robot, cfg, env.device)
        try:
            self.fc.sensor_columns(env.sim.sensors)
        except KeyError:
            raise ValueError(
                f"observation term {TERM!r}: the env model has no body pose sensors (sim={type(env.sim).__name__}); "
                "it is measured on sim=mujoco (physical or field obstacles)"
            ) from None
        fill_contact_sdf(env.scenes, cfg)

    def read(self, env: TraversalEnv) -> torch.Tensor:
        """(N, B) clearance of every env's bodies [m], in ``clearance_bodies`` order."""
        if self.fc is None:
            return torch.full((env.num_envs, self.width), CLEARANCE_CLIP, device=env.device)
        pos, quat = self.fc.poses(env.sim.sensordata)
        src = env.field_source
        d = self.fc.body_sdf(src.bank, src.field_idx, pos, quat)
        return d.clamp(-CLEARANCE_CLIP, CLEARANCE_CLIP).to(env.device)
