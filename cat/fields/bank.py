"""Field bank: HumanoidPF of many scenes × goals on one device, and the batched 13-link trilinear query.

Scenes may have different grid shapes (typical 75×50×38, procedural 125×125×40, indoor 125×125×50) and
origins. What the env reads is stored once where it can be: d and ∇d per *scene* (``SCENE_CHANNELS``), F
per *field* = (scene, goal) (``GOAL_CHANNELS``); the geodesic and U are not stored (nothing reads them).
Storage (:data:`STORAGES`) is float32, float16 (half the memory), or ``compact``: d, ∇d in float16 and F as three
int8 mantissas with a shared int8 power-of-two exponent (56 instead of 80 bytes per voxel with 12 goals); the
accuracy of each is measured in docs/fields.md. Two flat buffers addressed with 64-bit offsets
(see :mod:`cat.fields._bank_kernel`).

A bank is allocated from its layout (grid and goal count per scene) and filled scene by scene, so building
it never holds more than one scene's arrays on the host besides the bank itself.

Out-of-grid rule: a point's continuous index is clamped to the span of voxel centres ("clamp to edge") and
``inside`` is False for it.
"""

from __future__ import annotations

import ctypes
import os
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch
import warp as wp

from cat.fields._bank_kernel import query_kernel, vec7
from cat.fields._wp import get_device, run_concurrently
from cat.fields.body_points import BodyPoints, min_sdf_kernel
from cat.fields.config import FieldCfg
from cat.fields.field import Field
from cat.fields.grid import Grid
from cat.fields.humanoid_pf import humanoid_pf
from cat.fields.store import SceneFields, check_scene_fields

SCENE_CHANNELS = ("sdf", "gx", "gy", "gz")
GOAL_CHANNELS = ("fx", "fy", "fz")
QUERY_CHANNELS = ("fx", "fy", "fz", "sdf", "gx", "gy", "gz")
"""Channels of :attr:`FieldSample.values`."""


@dataclass(frozen=True)
class Storage:
    """How a bank stores its channels: d, ∇d per scene (``scene``), F per goal (``goal``)."""

    scene: torch.dtype
    scene_wp: type
    goal: torch.dtype
    goal_wp: type
    shared_exponent: bool = False  # F as 3 int8 mantissas and one int8 power-of-two exponent per voxel

    @property
    def goal_channels(self) -> int:
        """Stored numbers per voxel and goal (F, plus its exponent when shared)."""
        return len(GOAL_CHANNELS) + int(self.shared_exponent)

    def encode_force(self, force: torch.Tensor) -> torch.Tensor:
        """F (..., 3) as stored: floats cast on copy; shared exponent: F = m · 2^e with the largest |m| in
        [64, 127] (a relative error of at most 1/128 of the largest component), m = e = 0 where F is 0."""
        if not self.shared_exponent:
            return force
        f = torch.nan_to_num(force.to(torch.float32), nan=0.0, posinf=0.0, neginf=0.0)
        peak = f.abs().amax(-1, keepdim=True)
        _, e = torch.frexp(peak)  # peak = p · 2^e, p in [0.5, 1)
        e = torch.where(peak > 0, e - 7, 0).clamp(-126, 127)  # peak / 2^(e-7) in [64, 128); F = 0: m = e = 0
        inv_scale = ((127 - e) << 23).view(torch.float32)  # 2^-e exactly, from its float32 bits
        m = (f * inv_scale).round_().clamp_(-127, 127)
        return torch.cat([m, e.to(m.dtype)], -1).to(torch.int8)


STORAGES = {
    "float32": Storage(torch.float32, wp.float32, torch.float32, wp.float32),
    "float16": Storage(torch.float16, wp.float16, torch.float16, wp.float16),
    "compact": Storage(torch.float16, wp.float16, torch.int8, wp.int8, shared_exponent=True),
}
"""Bank storage by name (``FieldBank(dtype=...)``, the run's ``sim.field_storage``)."""


@dataclass(frozen=True)
class SceneLayout:
    """Storage of one scene: its grid and how many goal fields it has."""

    grid: Grid
    num_goals: int


@dataclass
class FieldSample:
    """Query result, torch tensors of shape (N, K, ...)."""

    values: torch.Tensor
    """(N, K, 7) channels :data:`QUERY_CHANNELS`: F, d, ∇d."""
    inside: torch.Tensor
    """(N, K) bool: the point lies in its field's grid box."""

    @property
    def force(self) -> torch.Tensor:
        return self.values[..., 0:3]

    @property
    def sdf(self) -> torch.Tensor:
        return self.values[..., 3]

    @property
    def grad_sdf(self) -> torch.Tensor:
        return self.values[..., 4:7]


def bank_bytes(layouts: Sequence[SceneLayout], dtype: str = "float32") -> int:
    """Storage a bank of ``layouts`` needs (bytes), without allocating it."""
    st = _storage(dtype)
    scene_b, goal_b = st.scene.itemsize * len(SCENE_CHANNELS), st.goal.itemsize * st.goal_channels
    return sum(lay.grid.num_voxels * (scene_b + goal_b * lay.num_goals) for lay in layouts)


def advise_huge_pages(t: torch.Tensor) -> bool:
    """Ask Linux to back a large CPU tensor with 2 MiB pages (``madvise(MADV_HUGEPAGE)``), best effort.

    The query's random gathers over a multi-GB bank miss the TLB on nearly every read with 4 KiB pages; huge
    pages cover 512× more memory per TLB entry. Returns whether the call was made and succeeded."""
    if sys.platform != "linux" or t.nbytes < 4 * _HUGE:
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        a0 = (t.data_ptr() + _HUGE - 1) & ~(_HUGE - 1)
        a1 = (t.data_ptr() + t.nbytes) & ~(_HUGE - 1)
        return libc.madvise(ctypes.c_void_p(a0), ctypes.c_size_t(a1 - a0), _MADV_HUGEPAGE) == 0
    except (OSError, AttributeError):
        return False


_HUGE = 1 << 21
_MADV_HUGEPAGE = 14


def _storage(name: str) -> Storage:
    if name not in STORAGES:
        raise ValueError(f"bank dtype (storage) must be one of {', '.join(STORAGES)}, got {name!r}")
    return STORAGES[name]


class FieldBank:
    """Fields of many scenes (mixed grid shapes) × goals. Field ``i`` = (scene ``field_scene[i]``, a goal).

    Allocate with a layout, then fill every scene with :meth:`set_scene` (or use :meth:`build`,
    :meth:`from_scenes`, :meth:`from_fields`). On the CPU the query is memory-bound gathers on one core
    per launch; ``num_threads`` > 1 splits the points over that many concurrent launches."""

    def __init__(
        self,
        layouts: Sequence[SceneLayout],
        dtype: str = "float32",
        device: str | torch.device = "cpu",
        num_threads: int | None = None,
    ):
        if not layouts:
            raise ValueError("FieldBank needs at least one scene")
        for lay in layouts:
            if lay.num_goals < 1:
                raise ValueError(f"every scene needs at least one goal field, got {lay.num_goals}")
        self.dtype_name = dtype
        self.storage = _storage(dtype)
        self.dtype, self._wp_scalar = self.storage.scene, self.storage.scene_wp
        self.device = torch.device(device)
        self.layouts = list(layouts)
        vox = np.array([lay.grid.num_voxels for lay in layouts], dtype=np.int64)
        goals = np.array([lay.num_goals for lay in layouts], dtype=np.int64)
        scene_offset = np.concatenate(([0], np.cumsum(vox)[:-1]))
        self.field_start = np.concatenate(([0], np.cumsum(goals))).astype(np.int64)
        field_scene = np.repeat(np.arange(len(layouts)), goals)
        field_vox = vox[field_scene]
        field_offset = np.concatenate(([0], np.cumsum(field_vox)[:-1]))
        dev, i64 = self.device, torch.int64
        self.scene_data = torch.empty(int(vox.sum()) * len(SCENE_CHANNELS), dtype=self.dtype, device=dev)
        self.goal_data = torch.empty(
            int(field_vox.sum()) * self.storage.goal_channels, dtype=self.storage.goal, device=dev
        )
        if dev.type == "cpu":  # before the first write: pages are allocated on touch
            advise_huge_pages(self.scene_data)
            advise_huge_pages(self.goal_data)
        self.scene_offset = torch.as_tensor(scene_offset, dtype=i64, device=dev)
        self.field_offset = torch.as_tensor(field_offset, dtype=i64, device=dev)
        self.field_scene = torch.as_tensor(field_scene, dtype=torch.int32, device=dev)
        self.scene_shape = torch.tensor([lay.grid.shape for lay in layouts], dtype=torch.int32, device=dev)
        self.scene_origin = torch.tensor([lay.grid.origin for lay in layouts], dtype=torch.float32, device=dev)
        self.scene_voxel = torch.tensor([lay.grid.voxel for lay in layouts], dtype=torch.float32, device=dev)
        self.goals = torch.zeros(len(field_scene), 3, dtype=torch.float32, device=dev)
        self.contact_data: torch.Tensor | None = None  # per-scene contact SDF (set_contact_sdf), one value per voxel
        self.contact_band: float | None = None  # the band it was made exact in (cat.envs.field_contact)
        self._inv_voxel = (1.0 / self.scene_voxel).contiguous()
        self._unfilled = set(range(len(layouts)))
        self._wp_device = get_device("cpu" if dev.type == "cpu" else f"cuda:{dev.index or 0}")
        self._set_ptr_shift(0)
        if num_threads is None:
            num_threads = min(2, os.cpu_count() or 1)
        self.num_threads = max(1, int(num_threads)) if self._wp_device.is_cpu else 1

    # --- layout ------------------------------------------------------------------------------------------
    @property
    def num_scenes(self) -> int:
        return len(self.layouts)

    @property
    def num_fields(self) -> int:
        return int(self.field_scene.shape[0])

    @property
    def nbytes(self) -> int:
        """Bytes of field storage (both buffers, and the contact SDF once set)."""
        extra = 0 if self.contact_data is None else self.contact_data.nbytes
        return self.scene_data.nbytes + self.goal_data.nbytes + extra

    def scene_grid(self, s: int) -> Grid:
        """Grid of scene ``s`` as placed in the bank (its origin includes any offset given at fill time)."""
        g = self.layouts[s].grid
        return Grid(tuple(self.scene_origin[s].tolist()), g.voxel, g.shape)

    def grid(self, i: int) -> Grid:
        """Grid of field ``i``."""
        return self.scene_grid(int(self.field_scene[i]))

    def fields_of(self, s: int) -> range:
        """Field indices of scene ``s`` (one per goal, in goal order)."""
        return range(int(self.field_start[s]), int(self.field_start[s + 1]))

    def field_bounds(self, field_idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Lower and upper corners (N, 3) of the grid boxes of fields ``field_idx`` (N,)."""
        s = self.field_scene[field_idx.to(self.device, torch.long)].long()
        lo = self.scene_origin[s]
        return lo, lo + self.scene_shape[s].to(torch.float32) * self.scene_voxel[s, None]

    # --- filling -----------------------------------------------------------------------------------------
    def _scene_view(self, s: int) -> torch.Tensor:
        n = self.layouts[s].grid.num_voxels
        c = len(SCENE_CHANNELS)
        o = int(self.scene_offset[s]) * c
        return self.scene_data[o : o + n * c].view(*self.layouts[s].grid.shape, c)

    def _field_view(self, i: int) -> torch.Tensor:
        grid = self.layouts[int(self.field_scene[i])].grid
        c = self.storage.goal_channels
        o = int(self.field_offset[i]) * c
        return self.goal_data[o : o + grid.num_voxels * c].view(*grid.shape, c)

    def set_scene(self, s: int, data: SceneFields | list[Field], offset=(0.0, 0.0, 0.0)) -> None:
        """Write scene ``s``'s d, ∇d and every goal's F; its grid origin and goals are shifted by ``offset``.

        Goal fields (``list[Field]``) are copied straight from their channels, without a ``SceneFields`` in
        between (the live perception loop fills a bank 10 times a second)."""
        if isinstance(data, SceneFields):
            grid, goals, sdf_grad, forces = data.grid, data.goals, data.sdf_grad, list(data.force)
        else:
            f0 = check_scene_fields(data)
            grid, goals, sdf_grad = f0.grid, np.stack([f.goal for f in data]), f0.data[..., 3:7]
            forces = [f.force for f in data]
        lay = self.layouts[s]
        if grid.shape != lay.grid.shape or not np.isclose(grid.voxel, lay.grid.voxel):
            raise ValueError(f"scene {s}: fields on grid {grid.shape}/{grid.voxel}, bank expects {lay.grid}")
        if len(forces) != lay.num_goals:
            raise ValueError(f"scene {s}: {len(forces)} goal fields, bank expects {lay.num_goals}")
        off = np.asarray(offset, dtype=np.float64).reshape(3)
        self._scene_view(s).copy_(torch.from_numpy(sdf_grad))
        for force, i in zip(forces, self.fields_of(s), strict=True):
            self._field_view(i).copy_(self.storage.encode_force(torch.from_numpy(force)))
        fs = self.fields_of(s)
        self.goals[fs.start : fs.stop] = torch.as_tensor(goals + off, dtype=torch.float32, device=self.device)
        self.scene_origin[s] = torch.as_tensor(np.asarray(grid.origin) + off, dtype=torch.float32)
        self._unfilled.discard(s)

    def set_field(self, i: int, f: Field, offset=(0.0, 0.0, 0.0)) -> None:
        """Replace field ``i``'s F and goal (e.g. a rebuild for a clicked goal in the same scene).

        d and ∇d belong to the scene and are left as they are: use :meth:`set_scene` for new obstacles."""
        s = int(self.field_scene[i])
        if f.grid.shape != self.layouts[s].grid.shape:
            raise ValueError(f"field grid {f.grid.shape} does not match scene {s}'s {self.layouts[s].grid.shape}")
        self._field_view(i).copy_(self.storage.encode_force(torch.from_numpy(np.ascontiguousarray(f.force))))
        self.goals[i] = torch.as_tensor(np.asarray(f.goal) + np.asarray(offset), dtype=torch.float32)

    def scene_sdf(self, s: int) -> np.ndarray:
        """(nx, ny, nz) float32 copy of scene ``s``'s d."""
        return self._scene_view(s)[..., 0].float().cpu().numpy()

    def set_contact_sdf(self, s: int, d: np.ndarray) -> None:
        """Scene ``s``'s contact SDF (its grid's shape): what :meth:`min_sdf_on_bodies` reads with ``contact=True``
        (``cat.fields.contact_sdf``). The first call allocates it for every scene as a copy of their d."""
        grid = self.layouts[s].grid
        if tuple(d.shape) != tuple(grid.shape):
            raise ValueError(f"scene {s}: contact SDF of shape {tuple(d.shape)}, the scene's grid is {grid.shape}")
        if self.contact_data is None:
            self._check_ready()
            self.contact_data = self.scene_data.view(-1, len(SCENE_CHANNELS))[:, 0].clone()
        o = int(self.scene_offset[s])
        self.contact_data[o : o + grid.num_voxels].copy_(torch.from_numpy(np.ascontiguousarray(d)).reshape(-1))

    @classmethod
    def build(
        cls,
        layouts: Sequence[SceneLayout],
        load: Callable[[int], SceneFields | list[Field]],
        offsets: Sequence | None = None,
        dtype: str = "float32",
        device: str | torch.device = "cpu",
        num_threads: int | None = None,
    ) -> FieldBank:
        """Allocate for ``layouts`` and fill scene ``s`` with ``load(s)`` one at a time (no full host copy)."""
        bank = cls(layouts, dtype, device, num_threads)
        for s in range(len(layouts)):
            bank.set_scene(s, load(s), (0.0, 0.0, 0.0) if offsets is None else offsets[s])
        return bank

    @classmethod
    def from_scenes(
        cls, scenes: Sequence[SceneFields | list[Field]], dtype: str = "float32", device="cpu", num_threads=None
    ) -> FieldBank:
        """One bank scene per entry (a ``SceneFields`` or the list of one scene's goal fields)."""
        layouts = [
            SceneLayout(s.grid, s.num_goals)
            if isinstance(s, SceneFields)
            else SceneLayout(check_scene_fields(s).grid, len(s))
            for s in scenes
        ]
        return cls.build(layouts, lambda s: scenes[s], dtype=dtype, device=device, num_threads=num_threads)

    @classmethod
    def from_fields(cls, fields: list[Field], dtype: str = "float32", device="cpu", num_threads=None) -> FieldBank:
        """Each field as its own scene (no sharing of d, ∇d): field ``i`` of the bank is ``fields[i]``."""
        if not fields:
            raise ValueError("FieldBank needs at least one field")
        return cls.from_scenes([[f] for f in fields], dtype, device, num_threads)

    # --- query -------------------------------------------------------------------------------------------
    def _set_ptr_shift(self, shift: int) -> None:
        """Address the buffers from base pointers ``shift`` elements *below* them, with every offset raised by
        ``shift``: the same memory, reached through offsets past 2^31 (or 2^32) elements. Tests use this to
        check 64-bit addressing without allocating a bank that large."""
        self._ptr_shift = int(shift)
        self._offsets = (self.scene_offset + shift, self.field_offset + shift)  # kept alive: Warp aliases them
        self._meta = [
            wp.from_torch(self._offsets[0], dtype=wp.int64),
            wp.from_torch(self.scene_shape, dtype=wp.vec3i),
            wp.from_torch(self.scene_origin, dtype=wp.vec3),
            wp.from_torch(self._inv_voxel, dtype=wp.float32),
            wp.from_torch(self.field_scene, dtype=wp.int32),
            wp.from_torch(self._offsets[1], dtype=wp.int64),
        ]

    def _pointers(self) -> tuple[int, int, list]:
        shift = self._ptr_shift
        scene = (self.scene_data.data_ptr() - shift * self.scene_data.element_size() * len(SCENE_CHANNELS)) % 2**64
        goal = (self.goal_data.data_ptr() - shift * self.goal_data.element_size() * self.storage.goal_channels) % 2**64
        return scene, goal, self._meta

    def _check_ready(self) -> None:
        if self._unfilled:
            raise RuntimeError(f"field bank: {len(self._unfilled)} scene(s) never filled, e.g. {min(self._unfilled)}")

    def query(self, field_idx: torch.Tensor, points: torch.Tensor, out: FieldSample | None = None) -> FieldSample:
        """Trilinear F, d, ∇d at ``points`` (N, K, 3) in fields ``field_idx`` (N,).

        Non-finite points get the value at the grid's first voxel and ``inside`` False. On the CPU a
        field index out of range raises IndexError (on CUDA it is the caller's job: no host sync here)."""
        self._check_ready()
        if points.ndim != 3 or points.shape[-1] != 3:
            raise ValueError(f"points must be (N, K, 3), got {tuple(points.shape)}")
        n, k = points.shape[:2]
        if field_idx.shape != (n,):
            raise ValueError(f"field_idx must be ({n},), got {tuple(field_idx.shape)}")
        pts = points.to(self.device, torch.float32).contiguous()
        idx = field_idx.to(self.device, torch.int32).contiguous()
        if self.device.type == "cpu" and n > 0:  # an out-of-range field index would read foreign memory
            lo, hi = int(idx.min()), int(idx.max())
            if lo < 0 or hi >= self.num_fields:
                raise IndexError(f"field_idx out of range [0, {self.num_fields}): min {lo}, max {hi}")
        if out is None:
            out = FieldSample(
                torch.empty((n, k, len(QUERY_CHANNELS)), dtype=torch.float32, device=self.device),
                torch.empty((n, k), dtype=torch.bool, device=self.device),
            )
        kernel = query_kernel(self.storage.scene_wp, self.storage.goal_wp)
        scene_ptr, goal_ptr, meta = self._pointers()
        values = out.values.view(-1, len(QUERY_CHANNELS))
        inside = out.inside.view(-1)

        def launch(e0: int, e1: int) -> None:
            if e1 <= e0:
                return
            wp.launch(
                kernel,
                dim=(e1 - e0) * k,
                inputs=[
                    scene_ptr,
                    goal_ptr,
                    *meta,
                    wp.from_torch(idx[e0:e1], dtype=wp.int32),
                    wp.from_torch(pts[e0:e1].view(-1, 3), dtype=wp.vec3),
                    k,
                    wp.from_torch(values[e0 * k : e1 * k], dtype=vec7),
                    wp.from_torch(inside[e0 * k : e1 * k], dtype=wp.bool),
                ],
                device=self._wp_device,
            )

        if self._wp_device.is_cuda:  # run on torch's current stream (no implicit sync, no race)
            with wp.ScopedStream(wp.stream_from_torch(self.device)):
                launch(0, n)
        else:
            parts = self.num_threads if n >= 256 else 1
            bounds = [n * t // parts for t in range(parts + 1)]
            run_concurrently(*[lambda t=t: launch(bounds[t], bounds[t + 1]) for t in range(parts)])
        return out

    def min_sdf_on_bodies(
        self,
        field_idx: torch.Tensor,
        pos: torch.Tensor,
        quat: torch.Tensor,
        bodies: BodyPoints,
        cull: bool = True,
        thread_per_body: bool | None = None,
        contact: bool = False,
    ) -> torch.Tensor:
        """(N, B) smallest d (less its group's offset) over each body's points of ``bodies``, posed by ``pos``
        (N, B, 3) and unit ``quat`` (N, B, 4; w, x, y, z), in fields ``field_idx`` (N,): one fused kernel
        (:mod:`cat.fields.body_points`).

        +inf where every point of the body lies outside its grid box or in a culled group (``cull=False``: none
        is culled). Interpolation and out-of-grid rule are :meth:`query`'s. ``thread_per_body``: one kernel thread
        per (world, body) instead of per world (default: on CUDA only; the result is the same). ``contact``: read
        the contact SDF (:meth:`set_contact_sdf`) instead of d."""
        self._check_ready()
        if contact and self.contact_data is None:
            raise RuntimeError("field bank: min_sdf_on_bodies(contact=True) but no contact SDF was set")
        n, nb = pos.shape[:2]
        if pos.shape != (n, bodies.num_bodies, 3) or quat.shape != (n, nb, 4) or field_idx.shape != (n,):
            raise ValueError(f"pos {tuple(pos.shape)} / quat {tuple(quat.shape)} / field_idx {tuple(field_idx.shape)}")
        out = torch.empty((n, nb), dtype=torch.float32, device=self.device)
        if n == 0:
            return out
        p = pos.to(self.device, torch.float32).contiguous().view(-1, 3)
        q = quat.to(self.device, torch.float32).contiguous().view(-1, 4)
        idx = field_idx.to(self.device, torch.int32).contiguous()
        if self.device.type == "cpu":  # an out-of-range field index would read foreign memory
            lo, hi = int(idx.min()), int(idx.max())
            if lo < 0 or hi >= self.num_fields:
                raise IndexError(f"field_idx out of range [0, {self.num_fields}): min {lo}, max {hi}")
        kernel = min_sdf_kernel(self._wp_scalar, 1 if contact else len(SCENE_CHANNELS))
        scene_ptr, _, meta = self._pointers()
        if contact:  # the same element offsets, one value per voxel
            scene_ptr = (self.contact_data.data_ptr() - self._ptr_shift * self.contact_data.element_size()) % 2**64
        # worlds of one scene in a row (they read the same grid: cache hits on the CPU); on the CPU one thread per
        # world (few thread starts), on CUDA one per (world, body)
        order = torch.argsort(idx, stable=True).to(torch.int32)
        split = int(self._wp_device.is_cuda if thread_per_body is None else thread_per_body)
        i32, f32, v3 = wp.int32, wp.float32, wp.vec3
        world = [wp.from_torch(idx, dtype=i32)]
        pose = [wp.from_torch(p, dtype=v3), wp.from_torch(q, dtype=wp.vec4), nb, split]
        shared = [
            wp.from_torch(bodies.body_start, dtype=i32),
            wp.from_torch(bodies.group_start, dtype=i32),
            wp.from_torch(bodies.centre, dtype=v3),
            wp.from_torch(bodies.cull, dtype=f32),
            wp.from_torch(bodies.offset, dtype=f32),
            wp.from_torch(bodies.points, dtype=v3),
            int(cull),
            wp.from_torch(out.view(-1), dtype=f32),
        ]

        def launch(e0: int, e1: int) -> None:  # worlds order[e0:e1]
            if e1 <= e0:
                return
            wp.launch(
                kernel,
                dim=(e1 - e0) * (nb if split else 1),
                inputs=[scene_ptr, *meta[:5], *world, wp.from_torch(order[e0:e1], dtype=i32), *pose, *shared],
                device=self._wp_device,
            )

        if self._wp_device.is_cuda:  # torch's current stream: no implicit sync
            with wp.ScopedStream(wp.stream_from_torch(self.device)):
                launch(0, n)
        else:
            parts = self.num_threads if n >= 64 else 1
            bounds = [n * t // parts for t in range(parts + 1)]
            run_concurrently(*[lambda t=t: launch(bounds[t], bounds[t + 1]) for t in range(parts)])
        return out

    def query_pf(
        self, field_idx: torch.Tensor, points: torch.Tensor, velocities: torch.Tensor, cfg: FieldCfg | None = None
    ) -> tuple[FieldSample, torch.Tensor]:
        """Query plus HumanoidPF at the links: (sample, F_H (N, K, 3)); link 0 is the root."""
        cfg = cfg or FieldCfg()
        s = self.query(field_idx, points)
        w0 = torch.full((points.shape[1],), cfg.w_other, dtype=torch.float32, device=self.device)
        w0[0] = cfg.w_root
        return s, humanoid_pf(s.force, s.grad_sdf, s.sdf, velocities.to(s.values), w0, cfg.lam)


__all__ = ["FieldBank", "FieldSample", "QUERY_CHANNELS", "STORAGES", "SceneLayout", "Storage", "bank_bytes"]
