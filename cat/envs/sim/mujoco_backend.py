"""``sim=mujoco``: N MuJoCo C worlds stepped across threads by ``mujoco.rollout`` (GIL-free, no Python per step).

State lives in one (N, nstate) float64 array (``mjSTATE_FULLPHYSICS``); qpos / qvel / sensordata are torch
views of host arrays, so the env reads them without copies. ``rollout`` returns the sensors of every
substep, so the ``max_sensors`` columns are a max over them. Contacts live in MuJoCo's arena; running out
of it is a fatal MuJoCo error (``mj_stackAlloc: out of memory``), never a silent drop.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence

import mujoco
import numpy as np
import torch
from mujoco import rollout

from cat.envs.sim.base import PhysicsBackend, as_index, state_layout


class MujocoBackend(PhysicsBackend):
    """MuJoCo C backend: ``decimation`` physics steps per call, threads over worlds."""

    def __init__(
        self,
        model: mujoco.MjModel,
        num_envs: int,
        decimation: int,
        nthread: int | None = None,
        max_sensors: Sequence[str] = (),
    ):
        super().__init__(model, num_envs, decimation, max_sensors)
        self.device = torch.device("cpu")
        self.nthread = nthread or max(1, min(os.cpu_count() or 1, num_envs))
        self._rollout = rollout.Rollout(nthread=self.nthread)
        self._datas = [mujoco.MjData(model) for _ in range(self.nthread)]
        self._scratch = mujoco.MjData(model)
        self._models: list[mujoco.MjModel] | None = None  # per-world copies once randomised
        self._shared_models = [model] * num_envs  # rollout wants one model per world when skipping checks

        self.nstate, self._qadr, self._vadr = state_layout(model)
        n, nu, ns = num_envs, model.nu, model.nsensordata
        self._state = np.zeros((n, self.nstate))
        self._sens_np = np.zeros((n, ns))
        self._ctrl = np.zeros((n, decimation, nu))
        self._out_state = np.zeros((n, decimation, self.nstate))
        self._out_sens = np.zeros((n, decimation, ns))
        self._qpos = torch.from_numpy(self._state[:, self._qadr : self._qadr + model.nq])
        self._qvel = torch.from_numpy(self._state[:, self._vadr : self._vadr + model.nv])
        self._sens = torch.from_numpy(self._sens_np)

        d = self._scratch
        mujoco.mj_resetData(model, d)
        if model.nkey > 0:
            mujoco.mj_resetDataKeyframe(model, d, 0)
        mujoco.mj_forward(model, d)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        mujoco.mj_getState(model, d, self._state[0], spec)
        self._state[:] = self._state[0]
        self._sens_np[:] = d.sensordata

    def step(self, ctrl: torch.Tensor) -> None:
        self._ctrl[:] = ctrl.detach().to("cpu", torch.float64).numpy()[:, None, :]
        self._rollout.rollout(
            self._models if self._models is not None else self._shared_models,
            self._datas,
            self._state,
            self._ctrl,
            skip_checks=True,
            nstep=self.decimation,
            state=self._out_state,
            sensordata=self._out_sens,
        )
        np.copyto(self._state, self._out_state[:, -1])
        np.copyto(self._sens_np, self._out_sens[:, -1])
        if self.max_columns:
            cols = self.max_columns
            self._sens_np[:, cols] = self._out_sens[:, :, cols].max(axis=1)

    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        ids = as_index(env_ids)
        if ids.size == 0:
            return
        qpos_np = qpos.detach().to("cpu", torch.float64).numpy().reshape(len(ids), -1)
        qvel_np = qvel.detach().to("cpu", torch.float64).numpy().reshape(len(ids), -1)
        d = self._scratch
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        for k, i in enumerate(ids):
            m = self._models[i] if self._models is not None else self.model
            mujoco.mj_resetData(m, d)
            d.qpos[:] = qpos_np[k]
            d.qvel[:] = qvel_np[k]
            mujoco.mj_forward(m, d)
            mujoco.mj_getState(m, d, self._state[i], spec)
            self._sens_np[i] = d.sensordata

    # --- domain randomisation: per-world model copies ---------------------------------------------------
    def _world_models(self) -> list[mujoco.MjModel]:
        if self._models is None:
            self._default_gain = self.model.actuator_gainprm[:, 0].copy()
            self._default_bias = self.model.actuator_biasprm[:, :3].copy()
            self._default_mass = self.model.body_mass.copy()
            self._default_inertia = self.model.body_inertia.copy()
            self._models = [copy.deepcopy(self.model) for _ in range(self.num_envs)]
        return self._models

    def set_actuator_gains(self, env_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
        models = self._world_models()
        kp_np, kd_np = kp.cpu().double().numpy(), kd.cpu().double().numpy()
        for k, i in enumerate(as_index(env_ids)):
            m = models[i]
            m.actuator_gainprm[:, 0] = kp_np[k]
            m.actuator_biasprm[:, 1] = -kp_np[k]
            m.actuator_biasprm[:, 2] = -kd_np[k]

    def set_body_mass_scale(self, env_ids: torch.Tensor, scale: torch.Tensor) -> None:
        models = self._world_models()
        s = scale.cpu().double().numpy()
        for k, i in enumerate(as_index(env_ids)):
            models[i].body_mass[:] = self._default_mass * s[k]
            models[i].body_inertia[:] = self._default_inertia * s[k][:, None]
