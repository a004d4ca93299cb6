"""Physics backends behind one interface: ``sim=mujoco`` (MuJoCo C, threads) and ``sim=warp`` (mujoco_warp)."""

from __future__ import annotations

import mujoco

from cat.envs.sim.base import PhysicsBackend

BACKENDS = ("mujoco", "warp")


def make_backend(
    name: str, model: mujoco.MjModel, num_envs: int, decimation: int, device: str = "cpu"
) -> PhysicsBackend:
    """Build the backend ``name`` for ``num_envs`` worlds; ``device`` is a torch device string."""
    if name == "mujoco":
        if not device.startswith("cpu"):
            raise ValueError(f"sim=mujoco runs on the CPU; got device={device!r}. Use sim=warp for CUDA.")
        from cat.envs.sim.mujoco_backend import MujocoBackend

        return MujocoBackend(model, num_envs, decimation)
    if name == "warp":
        from cat.envs.sim.warp_backend import WarpBackend

        return WarpBackend(model, num_envs, decimation, device="cpu" if device.startswith("cpu") else device)
    raise ValueError(f"unknown sim backend {name!r}; valid: {', '.join(BACKENDS)}")
