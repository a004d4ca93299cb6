"""Physics backends behind one interface: ``sim=mujoco`` (MuJoCo C, threads) and ``sim=warp`` (mujoco_warp)."""

from __future__ import annotations

from collections.abc import Sequence

import mujoco

from cat.envs.scene import COLLISION_SENSOR
from cat.envs.sim.base import PhysicsBackend

BACKENDS = ("mujoco", "warp")
PER_WORLD_BACKENDS = ("mujoco",)


def check_per_world(name: str) -> None:
    """Per-world scene models (``sim.per_world_scenes``) need ``sim=mujoco``; raise a clear error otherwise."""
    if name == "warp":
        raise NotImplementedError(
            "sim.per_world_scenes=true needs sim=mujoco. mujoco_warp 4.0 steps every world on one Model: it "
            "batches some fields per world (geom_dataid, geom_pos/quat/size/aabb, actuator gains, body masses) "
            "but not geom types or counts, so per-scene models cannot be swapped in (docs/scenes.md, 'Per-world "
            "scenes', describes the slot model that would be needed). With sim=warp use "
            "sim.per_world_scenes=false (scenes side by side on tiles)."
        )
    if name not in PER_WORLD_BACKENDS:
        raise ValueError(f"unknown sim backend {name!r}; valid: {', '.join(BACKENDS)}")


def make_backend(
    name: str,
    model: mujoco.MjModel,
    num_envs: int,
    decimation: int,
    device: str = "cpu",
    max_sensors: Sequence[str] | None = None,
) -> PhysicsBackend:
    """Build the backend ``name`` for ``num_envs`` worlds; ``device`` is a torch device string.

    ``max_sensors``: sensors reported as their maximum over the substeps of a control step; ``None``: the
    robot-obstacle contact sensor when the model has one (collisions count on every physics substep).
    """
    if max_sensors is None:
        names = {model.sensor(i).name for i in range(model.nsensor)}
        max_sensors = (COLLISION_SENSOR,) if COLLISION_SENSOR in names else ()
    if name == "mujoco":
        if not device.startswith("cpu"):
            raise ValueError(f"sim=mujoco runs on the CPU; got device={device!r}. Use sim=warp for CUDA.")
        from cat.envs.sim.mujoco_backend import MujocoBackend

        return MujocoBackend(model, num_envs, decimation, max_sensors=max_sensors)
    if name == "warp":
        from cat.envs.sim.warp_backend import WarpBackend

        dev = "cpu" if device.startswith("cpu") else device
        return WarpBackend(model, num_envs, decimation, device=dev, max_sensors=max_sensors)
    raise ValueError(f"unknown sim backend {name!r}; valid: {', '.join(BACKENDS)}")
