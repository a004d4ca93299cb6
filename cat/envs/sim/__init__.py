"""Physics backends behind one interface: ``sim=mujoco`` (MuJoCo C, threads) and ``sim=warp`` (mujoco_warp)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import mujoco

from cat.envs.sim.base import COLLISION_SENSOR, PART_SENSOR_PREFIX, PhysicsBackend

if TYPE_CHECKING:
    from cat.envs.scene_models import WorldModels

BACKENDS = ("mujoco", "warp")  # both support per-world scenes (``sim.per_world_scenes``; docs/scenes.md)


def check_backend(name: str) -> None:
    """Refuse an unknown backend name before anything is built.

    Per-world scene models: ``sim=mujoco`` swaps each world's model, ``sim=warp`` steps a slot model
    (``cat.envs.sim.warp_slots``); what the slots cannot represent (obstacle geoms other than mesh / box / height
    field, obstacle contact properties that differ between scenes) raises ``SlotError`` when the backend is built.
    """
    if name not in BACKENDS:
        raise ValueError(f"unknown sim backend {name!r}; valid: {', '.join(BACKENDS)}")


def make_backend(
    name: str,
    model: mujoco.MjModel,
    num_envs: int,
    decimation: int,
    device: str = "cpu",
    max_sensors: Sequence[str] | None = None,
    world_models: WorldModels | None = None,
    substep_sensors: Sequence[str] = (),
) -> PhysicsBackend:
    """Build the backend ``name`` for ``num_envs`` worlds; ``device`` is a torch device string.

    ``world_models``: per-world scenes; every world starts on ``world_models.models[0]`` (``assign_models``).

    ``max_sensors``: sensors reported as their maximum over the substeps of a control step; ``None``: the
    robot-obstacle contact sensors when the model has them (collisions count on every physics substep).
    ``substep_sensors``: sensors also kept for every substep (``PhysicsBackend.substep_sensordata``).
    """
    check_backend(name)
    if max_sensors is None:
        names = {model.sensor(i).name for i in range(model.nsensor)}
        max_sensors = tuple(n for n in sorted(names) if n == COLLISION_SENSOR or n.startswith(PART_SENSOR_PREFIX))
    if name == "mujoco":
        if not device.startswith("cpu"):
            raise ValueError(f"sim=mujoco runs on the CPU; got device={device!r}. Use sim=warp for CUDA.")
        from cat.envs.sim.mujoco_backend import MujocoBackend

        backend = MujocoBackend(model, num_envs, decimation, max_sensors=max_sensors, substep_sensors=substep_sensors)
        if world_models is not None:
            backend.set_model_table(world_models.models)
        return backend
    from cat.envs.sim.warp_backend import WarpBackend
    from cat.envs.sim.warp_slots import SlotTable

    dev = "cpu" if device.startswith("cpu") else device
    slots = SlotTable.build(world_models.models, world_models.compose) if world_models is not None else None
    return WarpBackend(
        model, num_envs, decimation, device=dev, max_sensors=max_sensors, slots=slots, substep_sensors=substep_sensors
    )
