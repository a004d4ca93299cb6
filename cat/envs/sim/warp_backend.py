"""``sim=warp``: N worlds of one model in mujoco_warp (``nworld=N``), state exposed as torch views.

``qpos`` / ``qvel`` / ``sensordata`` are ``wp.to_torch`` views of the mujoco_warp ``Data`` arrays (float32,
no copies); ``step`` writes ``ctrl`` into the ``d.ctrl`` view and runs ``decimation`` ``mjw.step`` calls,
captured once and replayed: a CUDA graph on CUDA; on the CPU device Warp's own capture/replay (Warp >= 1.19,
bitwise identical to eager launches, no Python launch overhead). On CUDA all torch and
warp work of the backend runs on one side stream ordered against the caller's current stream. (The CUDA
path could not be exercised on the 2-core, GPU-less dev machine; the tests cover the CPU device.)

``reset`` does what ``mj_resetData`` + setting qpos/qvel + ``mj_forward`` does for the chosen worlds: the
reset fields are zeroed with torch (``mjw.reset_data`` rebuilds its kernels on every call, ~60 ms of Python),
then ``mjw.forward`` runs on all worlds (no per-world mask there; forward changes no state of the others)
and the other worlds' ``sensordata`` is restored, keeping ``base.py``'s timing convention for them.

Parity with ``MujocoBackend`` (MuJoCo C): both run the options of the model as compiled (G1: implicitfast,
Newton, pyramidal cone), nothing needs aligning, and contacts come out identical (points, depths, counts).
With a converging solver the trajectories agree to float32 rounding (1 s of G1 control: qpos ~1e-5).
With the model's 5 Newton iterations the solve stops short of convergence and its result depends on the
starting point: mujoco_warp carries the warmstart across ``step`` calls like an ``mj_step`` loop, while
``mujoco.rollout`` restarts it at every call; this (and float32) makes contact-rich trajectories drift
apart by about as much as two MuJoCo C runs differing only in warmstart (mm in qpos, up to ~1 rad/s in
light joints' qvel over 1 s). See ``tests/test_sim_parity.py``. mujoco_warp flags unconverged solves
(``OverflowType.ITERATIONS``) in ``overflow``; that is routine (float32 vs a 1e-8 tolerance) and not printed.

Contact buffers are preallocated per world (``nconmax`` contacts, ``njmax`` constraint rows): a world that
exceeds them drops contacts and sets its bit in ``overflow``. ``step`` and ``reset`` check those bits and
raise (``check_overflow``), so a dropped contact is an error, never a silent undercount.

``max_sensors`` columns: a small kernel inside the captured decimation loop keeps their running max over the
substeps and writes it into ``sensordata`` after the last one; ``substep_sensors`` columns are copied into
``substep_sensordata`` after each substep by another.

Per-world scenes (``slots``, ``sim.per_world_scenes``): the backend steps a slot model
(``cat.envs.sim.warp_slots``) whose obstacle geom rows are batched per world; ``assign_models`` copies a table
model's rows (and its robot gains and masses, which pool members differ in) into the chosen worlds with torch
indexing on the ``wp.to_torch`` views: no reallocation, the captured graphs stay valid. World i then behaves as
``MujocoBackend`` world i on ``table[model_ids[i]]``.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence

import mujoco
import mujoco_warp as mjw
import numpy as np
import torch
import warp as wp

from cat.envs.sim.base import PhysicsBackend, write_pd_gains
from cat.envs.sim.warp_slots import SLOT_FIELDS, SlotTable, SlotWriter
from cat.fields import init_warp

logger = logging.getLogger(__name__)

#: Contacts per world (pooled over worlds: ``nconmax * N`` in total). Measured with MuJoCo C: the G1 on the
#: floor has <= 13 contacts even collapsed or lying flat; obstacles add a few per touching geom pair.
DEFAULT_NCONMAX = 48
#: Constraint rows per world (hard per-world limit): 4 per pyramidal condim-3 contact + active joint limits
#: (<= 29). Measured <= 81 on the floor; 192 leaves room for ~40 contacts. Larger costs speed (Warp CPU,
#: N=256: 320 rows is ~13 % slower than 192).
DEFAULT_NJMAX = 192
#: Overflow bits that mean dropped contacts / constraints (the others flag unconverged solves, not errors).
BUFFER_OVERFLOWS = (
    mjw.OverflowType.NEFC
    | mjw.OverflowType.NJMAX_NNZ
    | mjw.OverflowType.BROADPHASE
    | mjw.OverflowType.NARROWPHASE
    | mjw.OverflowType.CCD
    | mjw.OverflowType.HFIELD
    | mjw.OverflowType.CONTACT_MATCH
    | mjw.OverflowType.EPA_HORIZON
)

# Data fields ``mj_resetData`` zeroes (mujoco_warp ``reset_data``; qpos is set to qpos0 separately).
_ZEROED_FIELDS = (
    "qvel",
    "qacc_warmstart",
    "qfrc_applied",
    "qacc",
    "ctrl",
    "act",
    "act_dot",
    "userdata",
    "sensordata",
    "xfrc_applied",
    "time",
    "energy",
    "solver_niter",
    "ne",
    "nf",
    "nl",
    "nefc",
    "overflow",
)

# Model fields expanded over worlds so ``set_actuator_gains`` / ``set_body_mass_scale`` can randomise them.
_PER_WORLD_FIELDS = ("actuator_gainprm", "actuator_biasprm", "body_mass", "body_inertia", "body_subtreemass")


@wp.kernel
def _substep_max(sens: wp.array2d(dtype=float), cols: wp.array(dtype=int), acc: wp.array2d(dtype=float), first: int):
    """acc[w, j] = sens[w, cols[j]] on the first substep, else the running max."""
    w, j = wp.tid()
    v = sens[w, cols[j]]
    if first == 0:
        v = wp.max(v, acc[w, j])
    acc[w, j] = v


@wp.kernel
def _substep_copy(sens: wp.array2d(dtype=float), cols: wp.array(dtype=int), out: wp.array3d(dtype=float), k: int):
    """out[w, k, j] = sens[w, cols[j]]: the ``substep_sensors`` reading of substep ``k``."""
    w, j = wp.tid()
    out[w, k, j] = sens[w, cols[j]]


@wp.kernel
def _write_columns(acc: wp.array2d(dtype=float), cols: wp.array(dtype=int), sens: wp.array2d(dtype=float)):
    w, j = wp.tid()
    sens[w, cols[j]] = acc[w, j]


def resolve_device(device: str | torch.device | None) -> str:
    """Warp device name: ``None`` -> ``"cuda:0"`` when Warp sees a GPU, else ``"cpu"``."""
    init_warp()  # quiet start-up (cat.fields._wp)
    n_cuda = wp.get_cuda_device_count()
    device = str(device) if device is not None else None
    if device is None:
        return "cuda:0" if n_cuda > 0 else "cpu"
    if device == "cpu":
        return "cpu"
    if device.startswith("cuda"):
        index = int(device.split(":", 1)[1]) if ":" in device else 0
        if n_cuda == 0:
            raise RuntimeError(
                f"WarpBackend(device={device!r}) but Warp sees no CUDA device (no GPU, driver, or CUDA-enabled "
                "warp-lang). Use device='cpu' (slow: mujoco_warp is built for GPUs), device=None to pick "
                "automatically, or sim=mujoco for the MuJoCo C backend."
            )
        if index >= n_cuda:
            raise RuntimeError(f"WarpBackend(device={device!r}) but Warp sees only {n_cuda} CUDA device(s)")
        return f"cuda:{index}"
    raise ValueError(f"WarpBackend device must be None, 'cpu' or 'cuda[:i]', got {device!r}")


class WarpBackend(PhysicsBackend):
    """mujoco_warp backend: one ``Data`` with ``nworld = num_envs``, torch views of its arrays.

    Args:
        model: compiled scene (``cat.envs.scene.build_env_model``).
        num_envs: number of worlds N.
        decimation: physics steps per ``step`` call.
        device: ``"cpu"``, ``"cuda[:i]"`` or ``None`` (CUDA if available). Tensors live on the matching
            torch device.
        nconmax: contacts allocated per world (total ``nconmax * N``; a world may use more if others use
            fewer).
        njmax: constraint rows allocated per world (hard per-world limit).
        graph: capture the decimation loop and the reset's forward pass once and replay them (CUDA graphs;
            on the CPU, Warp >= 1.19 replays captured launches natively, skipping the Python overhead of
            mujoco_warp's ~140 kernel launches per physics step: 20x faster at N=3, ~1.5-2x at N=64-256).
            ``False``: launch eagerly.
        max_sensors: sensors reported as their max over the substeps (see ``cat.envs.sim.base``).
        slots: per-world scenes: step ``slots.model`` (``model`` is then only checked against it) with each
            world on a model of ``slots.table`` (``assign_models``; all start on model 0).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        num_envs: int,
        decimation: int,
        device: str | torch.device | None = None,
        nconmax: int = DEFAULT_NCONMAX,
        njmax: int = DEFAULT_NJMAX,
        graph: bool = True,
        max_sensors: Sequence[str] = (),
        slots: SlotTable | None = None,
        substep_sensors: Sequence[str] = (),
    ):
        if slots is not None:
            if slots.model.nsensordata != model.nsensordata or slots.model.nq != model.nq:
                raise ValueError("WarpBackend: slots.model does not fit model (sensors or state differ)")
            model = slots.model
        super().__init__(model, num_envs, decimation, max_sensors, substep_sensors)
        self.slots = slots
        self.wp_device = wp.get_device(resolve_device(device))
        self.device = torch.device(wp.device_to_torch(self.wp_device))
        self.nconmax, self.njmax = nconmax, njmax
        self.use_graph = graph
        self._stream: torch.cuda.Stream | None = None
        if self.wp_device.is_cuda:
            # Warp work runs on its own torch-known stream, ordered against the caller's stream (_sim_stream).
            self._stream = torch.cuda.Stream(device=self.device)
            self._wp_stream = wp.stream_from_torch(self._stream)

        with wp.ScopedDevice(self.wp_device):  # allocations land on the chosen device
            batch = {f: num_envs for f in _PER_WORLD_FIELDS}
            if slots is not None:  # >= 2 rows: mujoco_warp honours geom_dataid = -1 only when it is batched
                batch.update({f: max(num_envs, 2) for f in SLOT_FIELDS})
            self.m = mjw.put_model(model, batch_sizes=batch)
            self.m.opt.warn_overflow = int(BUFFER_OVERFLOWS)  # print buffer overflows, not solver iterations
            self.d = mjw.make_data(model, nworld=num_envs, nconmax=nconmax, njmax=njmax)
            self._reset_mask = wp.zeros(num_envs, dtype=bool)
            self._max_cols = wp.array(self.max_columns, dtype=int)
            self._max_acc = wp.zeros((num_envs, len(self.max_columns)), dtype=float)
            self._sub_cols = wp.array(self.substep_columns, dtype=int)
            self._sub_buf = wp.zeros((num_envs, decimation, len(self.substep_columns)), dtype=float)
        d = self.d
        self._qpos = wp.to_torch(d.qpos)
        self._qvel = wp.to_torch(d.qvel)
        self._ctrl = wp.to_torch(d.ctrl)
        self._sens = wp.to_torch(d.sensordata)
        self._overflow = wp.to_torch(d.overflow)
        self._mask_t = wp.to_torch(self._reset_mask)
        self._sens_saved = torch.empty_like(self._sens)
        self._sub = wp.to_torch(self._sub_buf)
        self._subtree: torch.Tensor | None = None  # (nbody, nbody) subtree membership, for mass scaling
        self._zeroed = [wp.to_torch(getattr(d, f)) for f in _ZEROED_FIELDS if getattr(d, f).size > 0]
        # model features whose reset state the torch reset does not cover: use mjw.reset_data (slower) then
        self._torch_reset = not (
            model.nmocap
            or model.neq
            or model.nflex
            or model.nplugin
            or self.m.nhistory
            or self.m.nplastic
            or model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP
        )
        self._model_ids = torch.zeros(num_envs, dtype=torch.long)
        self._writer: SlotWriter | None = None
        if slots is not None:
            views = {f: wp.to_torch(getattr(self.m, f)) for f in (*SLOT_FIELDS, *_PER_WORLD_FIELDS)}
            data_views = {f: wp.to_torch(getattr(d, f)) for f in ("geom_xpos", "geom_xmat")}
            self._writer = SlotWriter(slots, views, data_views)
            self.assign_models(torch.arange(num_envs), torch.zeros(num_envs, dtype=torch.long))

        with self._sim_stream():
            mjw.reset_data(self.m, d)
            if model.nkey > 0:
                mjw.reset_data_keyframe(self.m, d, 0)
            mjw.forward(self.m, d)
            if self.substep_columns:
                self._sub.copy_(self._sens[:, self.substep_columns].unsqueeze(1).expand_as(self._sub))
            self._step_graph = self._capture(self._physics_steps)
            self._forward_graph = self._capture(lambda: mjw.forward(self.m, self.d))
        logger.info(
            "WarpBackend: %d worlds on %s, nconmax=%d njmax=%d, graph replay: %s",
            num_envs,
            self.wp_device,
            nconmax,
            njmax,
            self._step_graph is not None,
        )

    # --- state views ---------------------------------------------------------------------------------
    @property
    def overflow(self) -> torch.Tensor:
        """(N,) int32 mujoco_warp ``OverflowType`` bits per world since its last reset (sticky)."""
        return self._overflow

    def check_overflow(self) -> None:
        """Raise if any world dropped contacts / constraints (``BUFFER_OVERFLOWS``); syncs with the device.

        Called by ``step`` and ``reset``; cheap when nothing overflowed (one reduction and a host read).
        """
        bits = self._overflow & int(BUFFER_OVERFLOWS)
        if not bool(bits.any()):
            return
        bits = bits.cpu()
        bad = torch.nonzero(bits).reshape(-1).tolist()
        if bad:
            flags = {f.name for f in mjw.OverflowType if f & BUFFER_OVERFLOWS and any(bits[i] & f for i in bad)}
            raise RuntimeError(
                f"mujoco_warp buffers overflowed in worlds {bad[:10]} ({', '.join(sorted(flags))}); "
                f"raise WarpBackend nconmax (now {self.nconmax}) / njmax (now {self.njmax})"
            )

    # --- stepping ------------------------------------------------------------------------------------
    def step(self, ctrl: torch.Tensor) -> None:
        with self._sim_stream():
            self._ctrl.copy_(ctrl)
            self._launch(self._step_graph, self._physics_steps)
        self.check_overflow()

    def reset(self, env_ids: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor) -> None:
        """Reset worlds ``env_ids`` as ``mj_resetData`` + state + ``mj_forward`` would; others keep everything."""
        ids = torch.as_tensor(env_ids, device=self.device, dtype=torch.long).reshape(-1)
        if ids.numel() == 0:
            return
        with self._sim_stream():
            self._mask_t.zero_()
            self._mask_t[ids] = True
            self._sens_saved.copy_(self._sens)
            if self._torch_reset:  # same effect as mjw.reset_data, without its per-call kernel rebuild (~60 ms)
                for t in self._zeroed:
                    t[ids] = 0
            else:
                mjw.reset_data(self.m, self.d, self._reset_mask)
            self._qpos[ids] = qpos.to(self._qpos).reshape(len(ids), -1)
            self._qvel[ids] = qvel.to(self._qvel).reshape(len(ids), -1)
            self._launch(self._forward_graph, lambda: mjw.forward(self.m, self.d))
            self._sens.copy_(torch.where(self._mask_t[:, None], self._sens, self._sens_saved))
            if self.substep_columns:
                self._sub[ids] = self._sens[ids][:, self.substep_columns].unsqueeze(1)
        self.check_overflow()

    def _physics_steps(self) -> None:
        ncol, nsub = len(self.max_columns), len(self.substep_columns)
        for k in range(self.decimation):
            mjw.step(self.m, self.d)
            if nsub:
                args = [self.d.sensordata, self._sub_cols, self._sub_buf, k]
                wp.launch(_substep_copy, dim=(self.num_envs, nsub), inputs=args)
            if ncol:
                dims, args = (self.num_envs, ncol), [self.d.sensordata, self._max_cols, self._max_acc, int(k == 0)]
                wp.launch(_substep_max, dim=dims, inputs=args)
        if ncol:
            wp.launch(
                _write_columns, dim=(self.num_envs, ncol), inputs=[self._max_acc, self._max_cols, self.d.sensordata]
            )

    def _capture(self, fn: Callable[[], None]) -> wp.Graph | None:
        """Graph of ``fn``'s launches (CUDA graph; on the CPU Warp's API-capture replay), ``None`` if disabled."""
        if not self.use_graph:
            return None
        with wp.ScopedCapture(device=self.wp_device) as capture:
            fn()
        return capture.graph

    def _launch(self, graph: wp.Graph | None, fn: Callable[[], None]) -> None:
        if graph is not None:
            wp.capture_launch(graph)
        else:
            fn()

    @contextlib.contextmanager
    def _sim_stream(self) -> Iterator[None]:
        """On CUDA: run torch and warp work on one side stream, ordered after / before the caller's stream."""
        if self._stream is None:
            with wp.ScopedDevice(self.wp_device):
                yield
            return
        caller = torch.cuda.current_stream(self.device)
        self._stream.wait_stream(caller)
        with torch.cuda.stream(self._stream), wp.ScopedDevice(self.wp_device), wp.ScopedStream(self._wp_stream):
            yield
        caller.wait_stream(self._stream)

    # --- per-world models (slots) ------------------------------------------------------------------------
    def set_model_table(self, models) -> None:
        """The table is fixed when the backend is built (``slots``): accepted only if it is that table."""
        if (
            self.slots is None
            or len(models) != len(self.slots.table)
            or any(a is not b for a, b in zip(models, self.slots.table, strict=True))
        ):
            raise NotImplementedError(
                "WarpBackend compiles its slot model from the model table when it is built: pass "
                "slots=SlotTable.build(models, world_models.compose) "
                "(cat.envs.sim.make_backend(..., world_models=...) does)"
            )

    def assign_models(self, env_ids, model_ids) -> None:
        """World ``env_ids[k]`` steps ``table[model_ids[k]]`` from now on (its state is left as it is: reset it)."""
        if self._writer is None:
            raise RuntimeError("assign_models needs a WarpBackend built with slots")
        ids = torch.as_tensor(env_ids, dtype=torch.long).reshape(-1).cpu()
        mids = torch.as_tensor(model_ids, dtype=torch.long).reshape(-1).cpu()
        if ((mids < 0) | (mids >= len(self.slots.table))).any():
            raise IndexError(f"model ids out of range for a table of {len(self.slots.table)} models")
        self._model_ids[ids] = mids
        with self._sim_stream():
            self._writer.write(ids.to(self.device), mids.to(self.device))

    @property
    def model_ids(self) -> torch.Tensor:
        """(N,) index into the model table of each world's model (zeros without slots)."""
        return self._model_ids.clone()

    @property
    def per_world_models(self) -> bool:
        return self.slots is not None

    # --- domain randomisation: per-world model arrays ---------------------------------------------------
    def set_actuator_gains(self, env_ids: torch.Tensor, kp: torch.Tensor, kd: torch.Tensor) -> None:
        ids = torch.as_tensor(env_ids, device=self.device, dtype=torch.long).reshape(-1)
        gain = wp.to_torch(self.m.actuator_gainprm)  # (N, nu, 10)
        bias = wp.to_torch(self.m.actuator_biasprm)
        kp, kd = kp.to(gain), kd.to(gain)
        with self._sim_stream():
            write_pd_gains(gain, bias, kp, kd, rows=ids)

    def set_body_mass_scale(self, env_ids: torch.Tensor, scale: torch.Tensor) -> None:
        """Scale body masses and inertias per world; subtree masses follow (MuJoCo uses them for the COM)."""
        ids = torch.as_tensor(env_ids, device=self.device, dtype=torch.long).reshape(-1)
        mass = wp.to_torch(self.m.body_mass)  # (N, nbody)
        inertia = wp.to_torch(self.m.body_inertia)  # (N, nbody, 3)
        subtree = wp.to_torch(self.m.body_subtreemass)
        m0 = torch.as_tensor(self.model.body_mass, dtype=mass.dtype, device=self.device)
        i0 = torch.as_tensor(self.model.body_inertia, dtype=mass.dtype, device=self.device)
        new_mass = m0 * scale.to(mass)
        with self._sim_stream():
            mass[ids] = new_mass
            inertia[ids] = i0 * scale.to(mass)[..., None]
            subtree[ids] = new_mass @ self._subtree_matrix().T

    def _subtree_matrix(self) -> torch.Tensor:
        """(nbody, nbody) 0/1 matrix: ``[i, j] = 1`` when body j is in the subtree of body i."""
        if self._subtree is None:
            self._subtree = torch.as_tensor(subtree_matrix(self.model), dtype=torch.float32, device=self.device)
        return self._subtree


def subtree_matrix(model: mujoco.MjModel) -> np.ndarray:
    """(nbody, nbody) 0/1 matrix with ``[i, j] = 1`` when body j is body i or one of its descendants."""
    n = model.nbody
    s = np.eye(n)
    for j in range(1, n):  # parents precede children in MuJoCo's body order
        p = model.body_parentid[j]
        while True:
            s[p, j] = 1.0
            if p == 0:
                break
            p = model.body_parentid[p]
    return s
