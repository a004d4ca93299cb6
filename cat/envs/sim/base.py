"""One interface for the physics backends (MuJoCo C threads, mujoco_warp).

A backend owns N copies of one compiled ``MjModel`` and exposes their state as torch tensors. Everything
the env needs beyond qpos/qvel (site poses and velocities, IMU, contacts) is read from MuJoCo *sensors*
that the scene builder adds to the model, so both backends produce it inside the simulator.

Timing convention (both backends): ``step`` holds ``ctrl`` for ``decimation`` physics steps. ``qpos`` and
``qvel`` are the state after the last step; ``sensordata`` is computed by MuJoCo at the start of the last
physics step (one physics step, 5 ms, before ``qpos``), as ``mj_step`` does. ``reset`` recomputes
sensors for the reset worlds from their new state.

Sensors named in ``max_sensors`` (the robot-obstacle contact count) instead report the maximum over all
``decimation`` physics steps of the control step, so an event that lasts less than a control step (a
touch at an intermediate substep) is never lost. Over a trial every simulated state is checked once.

Sensors named in ``substep_sensors`` (the body poses of field-judged contact) are also kept for every substep:
``substep_sensordata`` (N, decimation, k) holds their readings at the start of each physics step of the last control
step (the states s_0 … s_{decimation-1}, s_0 being the previous control step's final state), so a judgement made
from them sees the states the contact sensors see. After ``reset`` every substep holds the reset state's reading.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

COLLISION_SENSOR = "robot_obstacle_contact"
"""The robot-obstacle contact count sensor the scene builder adds (``cat.envs.scene``); reported as its maximum
over a control step's substeps (``max_sensors``)."""
PART_SENSOR_PREFIX = "obstacle_contact_"
"""Prefix of the per-body obstacle contact sensors (``cat.envs.scene.part_obstacle_sensor``), max over substeps too."""


def write_pd_gains(gainprm, biasprm, kp, kd, rows=None) -> None:
    """MuJoCo's encoding of a position servo's PD gains, written in this one place: force = gain0 ctrl + bias1 q +
    bias2 qdot with gain0 = kp, bias1 = -kp, bias2 = -kd. ``gainprm`` / ``biasprm``: an actuator's (10,) arrays
    (MjSpec), a model's (nu, 10) or per-world (N, nu, 10) arrays (numpy or torch, written in place); ``rows``
    indexes their leading dimension (e.g. the worlds to change; None: all)."""
    idx = () if rows is None else (rows,)
    gainprm[(*idx, Ellipsis, 0)] = kp
    biasprm[(*idx, Ellipsis, 1)] = -kp
    biasprm[(*idx, Ellipsis, 2)] = -kd


@dataclass
class SensorSlice:
    """Where one named sensor lives in ``sensordata``."""

    adr: int
    dim: int


class PhysicsBackend(ABC):
    """N parallel worlds of one MuJoCo model, stepped with PD targets and decimation inside the simulator."""

    #: torch device of all exposed tensors
    device: torch.device

    def __init__(
        self,
        model: mujoco.MjModel,
        num_envs: int,
        decimation: int,
        max_sensors: Sequence[str] = (),
        substep_sensors: Sequence[str] = (),
    ):
        if num_envs < 1:
            raise ValueError(f"num_envs must be >= 1, got {num_envs}")
        if decimation < 1:
            raise ValueError(f"decimation must be >= 1, got {decimation}")
        self.model = model
        self.num_envs = num_envs
        self.decimation = decimation
        self.sensors = {
            model.sensor(i).name: SensorSlice(int(model.sensor_adr[i]), int(model.sensor_dim[i]))
            for i in range(model.nsensor)
        }
        for key, names in (("max_sensors", max_sensors), ("substep_sensors", substep_sensors)):
            missing = [name for name in names if name not in self.sensors]
            if missing:
                raise KeyError(f"{key} {missing} not in the model; model sensors: {sorted(self.sensors)}")
        #: sensordata columns reduced with max over the substeps of a control step (see the module docstring)
        slices = [self.sensors[name] for name in max_sensors]
        self.max_columns = [c for s in slices for c in range(s.adr, s.adr + s.dim)]
        #: sensordata columns also kept for every substep (``substep_sensordata``), in this order
        slices = [self.sensors[name] for name in substep_sensors]
        self.substep_columns = [c for s in slices for c in range(s.adr, s.adr + s.dim)]
        #: world-steps in which the simulator reset a world on its own (MuJoCo's auto-reset on a bad qacc, which
        #: hides a divergence as a jump back to qpos0); counted since construction. mujoco_warp has no auto-reset:
        #: a diverged world shows as non-finite state instead.
        self.auto_resets = 0

    # --- state views (N, ...): backends set ``_qpos``, ``_qvel``, ``_sens`` to torch views of their state ----
    _qpos: torch.Tensor
    _qvel: torch.Tensor
    _sens: torch.Tensor
    _sub: torch.Tensor

    @property
    def qpos(self) -> torch.Tensor:
        """(N, nq) generalized positions after the last step."""
        return self._qpos

    @property
    def qvel(self) -> torch.Tensor:
        """(N, nv) generalized velocities after the last step."""
        return self._qvel

    @property
    def sensordata(self) -> torch.Tensor:
        """(N, nsensordata) sensor readings (see the module docstring for their timing)."""
        return self._sens

    @property
    def substep_sensordata(self) -> torch.Tensor:
        """(N, decimation, len(substep_columns)) readings of ``substep_columns`` at every substep (module docstring)."""
        return self._sub

    def sensor(self, name: str) -> torch.Tensor:
        """(N, dim) view of one named sensor."""
        try:
            s = self.sensors[name]
        except KeyError:
            raise KeyError(f"no sensor {name!r}; model sensors: {sorted(self.sensors)}") from None
        return self.sensordata[:, s.adr : s.adr + s.dim]

    # --- control -------------------------------------------------------------------------------------
    @abstractmethod
    def step(self, ctrl: torch.Tensor) -> None:
        """Apply actuator controls ``ctrl`` (N, nu) (PD position targets) for ``decimation`` physics steps."""

    @abstractmethod
    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Set the state of worlds ``env_ids`` (qpos (k, nq), qvel (k, nv)) and recompute their sensors."""

    # --- snapshots (exact resume of a training run) ---------------------------------------------------------
    def get_state(self) -> dict[str, torch.Tensor]:
        """Copies of every world's qpos, qvel and sensordata (and its model id with per-world models)."""
        state = {"qpos": self.qpos.clone(), "qvel": self.qvel.clone(), "sensordata": self.sensordata.clone()}
        if self.substep_columns:
            state["substeps"] = self.substep_sensordata.clone()
        if self.per_world_models:
            state["model_ids"] = self.model_ids
        return state

    def set_state(self, state: dict[str, torch.Tensor]) -> None:
        """Restore ``get_state``'s snapshot into all worlds (sensors as they were, not recomputed)."""
        if state["qpos"].shape != self.qpos.shape:
            raise ValueError(
                f"sim snapshot of shape {tuple(state['qpos'].shape)} does not fit {tuple(self.qpos.shape)}"
            )
        if self.per_world_models != ("model_ids" in state):
            raise ValueError("sim snapshot and backend disagree on per-world models (model_ids)")
        if self.per_world_models:
            self.assign_models(torch.arange(self.num_envs), state["model_ids"])
        self.reset(torch.arange(self.num_envs), state["qpos"], state["qvel"])
        self._sens.copy_(state["sensordata"].to(self._sens))
        if self.substep_columns:  # a snapshot from before substep sensors existed: the last substep's reading
            sub = state.get("substeps")
            if sub is None or sub.shape != self._sub.shape:
                sub = self._sens[:, self.substep_columns].unsqueeze(1)
            self._sub.copy_(sub.to(self._sub))

    # --- per-world models (sim.per_world_scenes) ---------------------------------------------------------
    @property
    def per_world_models(self) -> bool:
        """Whether each world steps its own model of a table (``set_model_table``)."""
        return False

    @property
    def model_ids(self) -> torch.Tensor:
        """(N,) index into the model table of each world's model."""
        raise NotImplementedError(f"{type(self).__name__} does not support per-world models")

    def set_model_table(self, models: Sequence[mujoco.MjModel]) -> None:
        """Let each world step its own model of ``models`` (``assign_models``); backends that cannot raise."""
        raise NotImplementedError(f"{type(self).__name__} does not support per-world models")

    def assign_models(self, env_ids: torch.Tensor, model_ids: torch.Tensor) -> None:
        """World ``env_ids[k]`` steps ``models[model_ids[k]]`` of the table from its next reset on."""
        raise NotImplementedError(f"{type(self).__name__} does not support per-world models")

    # --- domain randomisation -------------------------------------------------------------------------
    def set_actuator_gains(self, env_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
        """Per-world PD gains (k, nu); backends that cannot randomise raise ``NotImplementedError``."""
        raise NotImplementedError(f"{type(self).__name__} does not support per-world actuator gains")

    def set_body_mass_scale(self, env_ids: torch.Tensor, scale: torch.Tensor) -> None:
        """Per-world body mass scale (k, nbody)."""
        raise NotImplementedError(f"{type(self).__name__} does not support per-world body masses")


def state_layout(model: mujoco.MjModel) -> tuple[int, int, int]:
    """(nstate, qpos offset, qvel offset) of ``mjSTATE_FULLPHYSICS`` state vectors."""
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    nstate = mujoco.mj_stateSize(model, spec)
    qpos_adr = mujoco.mj_stateSize(model, mujoco.mjtState.mjSTATE_TIME)
    return nstate, qpos_adr, qpos_adr + model.nq


def as_index(env_ids: torch.Tensor | np.ndarray | list[int]) -> np.ndarray:
    """Env ids as a 1-D int64 numpy array (host)."""
    if isinstance(env_ids, torch.Tensor):
        return env_ids.detach().to("cpu", torch.int64).numpy().reshape(-1)
    return np.asarray(env_ids, dtype=np.int64).reshape(-1)
