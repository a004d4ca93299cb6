"""``sim=mujoco``: N MuJoCo C worlds stepped across threads by ``mujoco.rollout`` (GIL-free, no Python per step).

State lives in one (N, nstate) float64 array (``mjSTATE_FULLPHYSICS``); qpos / qvel / sensordata are torch
views of host arrays, so the env reads them without copies. ``rollout`` returns the sensors of every
substep, so the ``max_sensors`` columns are a max over them. Contacts live in MuJoCo's arena; running out
of it is a fatal MuJoCo error (``mj_stackAlloc: out of memory``), never a silent drop.

Per-world models (``set_model_table``, ``sim.per_world_scenes``): world i steps ``table[model_ids[i]]``, and
``assign_models`` swaps that pointer (a scene change at reset, no rebuild). ``rollout`` shares one ``MjData`` per
thread among the worlds it steps, so the table's models are grouped by ``MjData`` layout
(``cat.envs.sim.layout.data_layout``) and each layout class present runs as its own rollout, with its own
``MjData``, on that class's worlds (gathered, stepped, scattered back).
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence

import mujoco
import numpy as np
import torch
from mujoco import rollout

from cat.envs.sim.base import PhysicsBackend, as_index, state_layout, write_pd_gains
from cat.envs.sim.layout import check_compatible, check_same_layout, data_layout


def set_model_gains(m: mujoco.MjModel, kp: np.ndarray, kd: np.ndarray) -> None:
    """PD gains (nu,) of a model's position actuators."""
    write_pd_gains(m.actuator_gainprm, m.actuator_biasprm, kp, kd)


def set_model_mass_scale(m: mujoco.MjModel, scale, mass0: np.ndarray, inertia0: np.ndarray) -> None:
    """Body masses and inertias = defaults ``mass0`` (nbody,) / ``inertia0`` (nbody, 3) x ``scale`` (scalar or
    (nbody,))."""
    s = np.broadcast_to(np.asarray(scale, dtype=np.float64), mass0.shape)
    m.body_mass[:] = mass0 * s
    m.body_inertia[:] = inertia0 * s[:, None]


class MujocoBackend(PhysicsBackend):
    """MuJoCo C backend: ``decimation`` physics steps per call, threads over worlds."""

    def __init__(
        self,
        model: mujoco.MjModel,
        num_envs: int,
        decimation: int,
        nthread: int | None = None,
        max_sensors: Sequence[str] = (),
        substep_sensors: Sequence[str] = (),
    ):
        super().__init__(model, num_envs, decimation, max_sensors, substep_sensors)
        self.device = torch.device("cpu")
        self.nthread = nthread or max(1, min(os.cpu_count() or 1, num_envs))
        self._rollout = rollout.Rollout(nthread=self.nthread)
        self._datas = [mujoco.MjData(model) for _ in range(self.nthread)]
        self._scratch = mujoco.MjData(model)
        self._models: list[mujoco.MjModel] | None = None  # per-world copies once randomised
        self._shared_models = [model] * num_envs  # rollout wants one model per world when skipping checks
        self._table: list[mujoco.MjModel] | None = None  # per-world models (set_model_table)
        self._model_ids = np.zeros(num_envs, dtype=np.int64)
        self._classes: dict[int, np.ndarray] | None = None

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
        self._sub_np = np.zeros((n, decimation, len(self.substep_columns)))
        self._sub = torch.from_numpy(self._sub_np)

        d = self._scratch
        mujoco.mj_resetData(model, d)
        if model.nkey > 0:
            mujoco.mj_resetDataKeyframe(model, d, 0)
        mujoco.mj_forward(model, d)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        mujoco.mj_getState(model, d, self._state[0], spec)
        self._state[:] = self._state[0]
        self._sens_np[:] = d.sensordata
        self._sub_np[:] = d.sensordata[self.substep_columns]

    def step(self, ctrl: torch.Tensor) -> None:
        self._ctrl[:] = ctrl.detach().to("cpu", torch.float64).numpy()[:, None, :]
        if self._table is not None and len(self._class_worlds()) > 1:
            self._step_classes()
            return
        if self._table is not None:
            models, datas = self._shared_models, self._class_datas[self._world_class[0]]
        else:
            models, datas = self._models if self._models is not None else self._shared_models, self._datas
        self._rollout.rollout(
            models,
            datas,
            self._state,
            self._ctrl,
            skip_checks=True,
            nstep=self.decimation,
            state=self._out_state,
            sensordata=self._out_sens,
        )
        self._take_outputs(slice(None), self._out_state, self._out_sens)

    def _step_classes(self) -> None:
        """One rollout per layout class present, on that class's worlds (gathered into contiguous buffers)."""
        for c, ids in self._class_worlds().items():
            n = len(ids)
            out_state, out_sens = self._out_state[:n], self._out_sens[:n]
            self._rollout.rollout(
                self._class_models[c],
                self._class_datas[c],
                self._state[ids],
                self._ctrl[ids],
                skip_checks=True,
                nstep=self.decimation,
                state=out_state,
                sensordata=out_sens,
            )
            self._take_outputs(ids, out_state, out_sens)

    def _take_outputs(self, ids: np.ndarray | slice, out_state: np.ndarray, out_sens: np.ndarray) -> None:
        """Last substep's state and sensors of worlds ``ids``; ``max_columns`` as the max over the substeps.

        A world whose clock did not advance by ``decimation`` timesteps was reset by MuJoCo inside the rollout
        (``mj_resetData`` after a bad qacc sets time to 0): counted in ``auto_resets``."""
        expected = self._state[ids, 0] + self.decimation * self.model.opt.timestep
        self.auto_resets += int(np.count_nonzero(np.abs(out_state[:, -1, 0] - expected) > 1e-6))
        self._state[ids] = out_state[:, -1]
        self._sens_np[ids] = out_sens[:, -1]
        if self.max_columns:
            rows = ids if isinstance(ids, slice) else ids[:, None]
            self._sens_np[rows, self.max_columns] = out_sens[:, :, self.max_columns].max(axis=1)
        if self.substep_columns:
            self._sub_np[ids] = out_sens[:, :, self.substep_columns]

    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        ids = as_index(env_ids)
        if ids.size == 0:
            return
        qpos_np = qpos.detach().to("cpu", torch.float64).numpy().reshape(len(ids), -1)
        qvel_np = qvel.detach().to("cpu", torch.float64).numpy().reshape(len(ids), -1)
        d = self._scratch
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        for k, i in enumerate(ids):
            m = self._models[i] if self._models is not None else self._shared_models[i]
            if self._table is not None:
                d = self._class_scratch[self._world_class[i]]
            mujoco.mj_resetData(m, d)
            d.qpos[:] = qpos_np[k]
            d.qvel[:] = qvel_np[k]
            mujoco.mj_forward(m, d)
            mujoco.mj_getState(m, d, self._state[i], spec)
            self._sens_np[i] = d.sensordata
            self._sub_np[i] = d.sensordata[self.substep_columns]

    # --- per-world models ----------------------------------------------------------------------------------
    def set_model_table(self, models: Sequence[mujoco.MjModel]) -> None:
        """Let worlds step models of ``models`` (all with this backend's state, control and sensor sizes); every
        world starts on ``models[0]``. ``assign_models`` picks each world's model."""
        if self._models is not None:
            raise RuntimeError("set_model_table after per-world gains or masses were set")
        models = list(models)
        check_compatible([self.model, *models], ["the backend's model"] + [f"model {i}" for i in range(len(models))])
        layouts: dict[tuple, int] = {}
        self._table_class = np.array([layouts.setdefault(data_layout(m), len(layouts)) for m in models])
        for c in range(len(layouts)):  # rollout would write past a shared MjData's arrays otherwise
            check_same_layout([models[i] for i in np.flatnonzero(self._table_class == c)])
        first = {c: models[int(np.flatnonzero(self._table_class == c)[0])] for c in range(len(layouts))}
        self._class_datas = [[mujoco.MjData(first[c]) for _ in range(self.nthread)] for c in range(len(layouts))]
        self._class_scratch = [mujoco.MjData(first[c]) for c in range(len(layouts))]
        self._table = models
        self.assign_models(np.arange(self.num_envs), np.zeros(self.num_envs, dtype=np.int64))

    @property
    def num_layouts(self) -> int:
        """MjData layout classes of the model table (one rollout each per step when present); 1 without one."""
        return 1 if self._table is None else len(self._class_datas)

    def assign_models(self, env_ids, model_ids) -> None:
        """World ``env_ids[k]`` steps ``table[model_ids[k]]`` from now on (its state is left as it is: reset it)."""
        if self._table is None:
            raise RuntimeError("assign_models needs set_model_table first")
        ids, mids = as_index(env_ids), as_index(model_ids)
        if ((mids < 0) | (mids >= len(self._table))).any():
            raise IndexError(f"model ids out of range for a table of {len(self._table)} models")
        self._model_ids[ids] = mids
        for i, m in zip(ids.tolist(), mids.tolist(), strict=True):
            self._shared_models[i] = self._table[m]
        self._world_class = self._table_class[self._model_ids]
        self._classes = None

    @property
    def model_ids(self) -> torch.Tensor:
        """(N,) index into the model table of each world's model (zeros without a table)."""
        return torch.from_numpy(self._model_ids.copy())

    def _class_worlds(self) -> dict[int, np.ndarray]:
        """Layout class -> its worlds (sorted), for the classes present; cached until the next assignment."""
        if self._classes is None:
            self._classes = {int(c): np.flatnonzero(self._world_class == c) for c in np.unique(self._world_class)}
            self._class_models = {c: [self._shared_models[i] for i in ids] for c, ids in self._classes.items()}
        return self._classes

    @property
    def per_world_models(self) -> bool:
        return self._table is not None

    # --- domain randomisation: per-world model copies ---------------------------------------------------
    def _world_models(self) -> list[mujoco.MjModel]:
        if self._table is not None:
            raise RuntimeError(
                "per-world models (set_model_table): gains and masses come with each world's model "
                "(cat.envs.scene_models.WorldModels pools), not from set_actuator_gains / set_body_mass_scale"
            )
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
            set_model_gains(models[i], kp_np[k], kd_np[k])

    def set_body_mass_scale(self, env_ids: torch.Tensor, scale: torch.Tensor) -> None:
        models = self._world_models()
        s = scale.cpu().double().numpy()
        for k, i in enumerate(as_index(env_ids)):
            set_model_mass_scale(models[i], s[k], self._default_mass, self._default_inertia)
