"""Per-world scenes on mujoco_warp: one *slot model* whose obstacle geom rows differ per world.

mujoco_warp steps every world on one ``Model``; geom types, contact bits and the geom count are shared, but
``geom_dataid`` / ``geom_pos`` / ``geom_quat`` / ``geom_size`` / ``geom_aabb`` / ``geom_rbound`` can be batched
per world (``put_model(batch_sizes=...)``). So the slot model holds the robot, every mesh and height field of
every scene model of the table as assets, and on the static obstacle body, per obstacle kind (mesh, box, height
field), as many geom *slots* as the table model that uses most of that kind. A world's slot rows are copied from
a *catalogue*: one compiled geom per obstacle geom of each distinct table model (in world coordinates), plus one
parked entry per kind:

* a mesh slot a scene does not fill gets ``geom_dataid = -1``: mujoco_warp's broadphase drops such a geom from
  that world (``collision_driver._mesh_missing``, used by the SAP and NxN broadphases when ``geom_dataid`` is
  batched, i.e. has more than one row), so it never reaches the narrow phase;
* box and height-field slots are parked ``PARK_Z`` below the floor (boxes 1 mm, height fields at their own
  size): they stay in the broadphase sweep of their world but are out of everyone's reach.

Static geoms' world poses (``Data.geom_xpos`` / ``geom_xmat``) are computed by mujoco_warp once, in ``make_data``,
never in ``kinematics`` (``smooth._geom_local_to_global`` skips bodies welded to the world), so a scene change
writes them too. Meshes re-added from a compiled model's vertices are compiled again; the catalogue and the slot
model compile identical asset lists, checked equal after compiling.
"""

from __future__ import annotations

import hashlib
import logging
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np
import torch

from cat.envs.sim.layout import PAD_BODY, SceneModelError, check_compatible
from cat.terrain.mujoco_export import OBSTACLE_BODY, obstacle_geom_ids

log = logging.getLogger(__name__)

# compose(add_obstacles) -> the env model with the obstacles the hook adds (``cat.envs.scene.model_composer``)
Composer = Callable[[Callable[[mujoco.MjSpec], None]], mujoco.MjModel]

PARK_Z = -50.0  # m: unused box / height-field slots sit this far below the floor
PARK_BOX = 1e-3  # m: half size of a parked box slot
_NO_BIT = 1 << 30  # a contact bit no geom has in contype: a geom with only this affinity touches nothing
_MESH, _BOX, _HFIELD = mujoco.mjtGeom.mjGEOM_MESH, mujoco.mjtGeom.mjGEOM_BOX, mujoco.mjtGeom.mjGEOM_HFIELD
KINDS = {int(_MESH): "mesh", int(_BOX): "box", int(_HFIELD): "hfield"}
#: Model geom fields batched per world by the slot path (the rows a scene change rewrites).
SLOT_FIELDS = ("geom_dataid", "geom_pos", "geom_quat", "geom_size", "geom_aabb", "geom_rbound")
#: Contact properties every obstacle geom of the table must share (slots carry one value for all worlds).
SHARED_PROPS = (
    "geom_contype", "geom_conaffinity", "geom_condim", "geom_priority", "geom_solmix", "geom_solref",
    "geom_solimp", "geom_friction", "geom_margin", "geom_gap",
)  # fmt: skip
#: Robot physics each world takes from its table model (domain-randomisation pools differ there).
ROBOT_FIELDS = ("actuator_gainprm", "actuator_biasprm", "body_mass", "body_inertia", "body_subtreemass")


class SlotError(SceneModelError):
    """A model table the slot model cannot represent (named geom type or contact property)."""


@dataclass
class SlotTable:
    """The slot model of a model table and, per table model, which catalogue row fills each slot.

    ``catalogue`` maps ``SLOT_FIELDS`` and ``geom_xpos`` / ``geom_xmat`` to (C, ...) arrays in the slot model's
    ids and MuJoCo's layouts (aabb as (C, 2, 3), xmat as (C, 3, 3)); ``rows[t, k]`` is slot ``k``'s catalogue
    row in table model ``t``; ``geoms[k]`` is slot ``k``'s geom id in ``model``."""

    model: mujoco.MjModel
    table: list[mujoco.MjModel]
    geoms: np.ndarray
    rows: np.ndarray
    catalogue: dict[str, np.ndarray]
    counts: dict[str, int]

    @classmethod
    def build(cls, table: Sequence[mujoco.MjModel], compose: Composer) -> SlotTable:
        """Slot model (robot + slots) of ``table`` (per-world scene models, ``cat.envs.scene_models``);
        ``compose(add_obstacles)`` compiles the env model with the obstacles a hook adds (``WorldModels.compose``:
        the env's composition is handed in, not imported)."""
        table = list(table)
        uniq: dict[str, int] = {}
        model_uniq = [uniq.setdefault(_geometry_key(m), len(uniq)) for m in table]
        firsts = [table[model_uniq.index(u)] for u in range(len(uniq))]
        obstacles = [_obstacle_geoms(m, f"table model {model_uniq.index(u)}") for u, m in enumerate(firsts)]
        props = _shared_props(table)
        cell_names = _cell_bodies(table[0])
        assets = _Assets()
        cat_spec, entries = _catalogue_spec(firsts, obstacles, assets)
        cat_body = cat_spec.body(OBSTACLE_BODY)
        counts = {name: max([sum(t == k for t, _ in e) for e in entries] or [0]) for k, name in KINDS.items()}
        parked = {k: len(cat_body.geoms) + i for i, k in enumerate(t for t in KINDS if counts[KINDS[t]])}
        for t in parked:
            _add_slot(cat_body, t, assets)
        assets.add_to(cat_spec)
        catalogue_model = cat_spec.compile()

        def add_slots(spec: mujoco.MjSpec) -> None:
            assets.add_to(spec)
            body = spec.worldbody.add_body(name=OBSTACLE_BODY)
            for cell in cell_names:  # the scene models' (empty here) cell bodies, so the bodies match by index
                body.add_body(name=cell)
            for t in KINDS:
                for k in range(counts[KINDS[t]]):
                    _add_slot(body, t, assets, name=f"slot_{KINDS[t]}_{k}")
            # bodies as in the scene models (masses copy by index). MuJoCo builds a mesh's convex hull (the graph
            # and polygons mujoco_warp's narrow phase reads) only for meshes a geom with contact bits references:
            # one geom per mesh whose only bit is _NO_BIT (in no broadphase pair; static: no per-step pose)
            pad = spec.worldbody.add_body(name=PAD_BODY)
            for name in assets.mesh_names:
                pad.add_geom(type=_MESH, meshname=name, contype=0, conaffinity=_NO_BIT, group=5, pos=[0.0, 0.0, PARK_Z])

        model = compose(add_slots)
        check_compatible([table[0], model], ["table model 0", "the slot model"])
        _check_bodies(table[0], model)
        assets.check_same(catalogue_model, model)
        if (model.geom_contype & _NO_BIT).any():
            raise SlotError(f"a geom of the slot model has contact bit {_NO_BIT} in contype (reserved here)")
        slot_body = model.body(OBSTACLE_BODY).id
        geoms = np.flatnonzero(model.geom_bodyid == slot_body)
        for name, value in props.items():
            getattr(model, name)[geoms] = value
        slot_types = model.geom_type[geoms]
        rows = np.empty((len(table), len(geoms)), dtype=np.int64)
        for u, e in enumerate(entries):
            r = np.array([parked[int(t)] for t in slot_types], dtype=np.int64)
            for t in parked:
                mine = [c for tt, c in e if tt == t]
                r[np.flatnonzero(slot_types == t)[: len(mine)]] = mine
            rows[np.asarray(model_uniq) == u] = r
        catalogue = _catalogue_rows(catalogue_model, model, parked.get(int(_MESH)))
        log.info(
            "warp slot model: %d table models (%d distinct), slots %s, catalogue %d rows",
            len(table),
            len(uniq),
            counts,
            len(catalogue["geom_dataid"]),
        )
        return cls(model, table, geoms, rows, catalogue, counts)


def _catalogue_spec(
    models: Sequence[mujoco.MjModel], obstacles: Sequence[np.ndarray], assets: _Assets
) -> tuple[mujoco.MjSpec, list[list[tuple[int, int]]]]:
    """A spec with one geom per obstacle geom of ``models``, at its world pose, on a static body at the origin;
    per model its (geom type, catalogue index) list. Meshes and height fields are collected into ``assets``."""
    spec = mujoco.MjSpec()
    body = spec.worldbody.add_body(name=OBSTACLE_BODY)
    entries = []
    for m, geoms in zip(models, obstacles, strict=True):
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        out = []
        for g in geoms:
            out.append((int(m.geom_type[g]), len(body.geoms)))
            quat = np.zeros(4)
            mujoco.mju_mat2Quat(quat, d.geom_xmat[g])
            kw = dict(type=int(m.geom_type[g]), pos=d.geom_xpos[g].tolist(), quat=quat.tolist())
            if m.geom_type[g] == _MESH:
                kw["meshname"] = assets.mesh(m, int(m.geom_dataid[g]))
            elif m.geom_type[g] == _HFIELD:
                kw["hfieldname"] = assets.hfield(m, int(m.geom_dataid[g]))
            else:
                kw["size"] = m.geom_size[g].tolist()
            body.add_geom(**kw)
        entries.append(out)
    return spec, entries


def _add_slot(body: mujoco.MjsBody, geom_type: int, assets: _Assets, name: str = "") -> None:
    """A parked geom of ``geom_type`` (its rows are overwritten per world)."""
    kw: dict = dict(name=name, type=geom_type, pos=[0.0, 0.0, PARK_Z])
    if geom_type == _MESH:
        kw["meshname"] = assets.mesh_names[0]
    elif geom_type == _HFIELD:
        kw["hfieldname"] = assets.hfield_names[0]
    else:
        kw["size"] = [PARK_BOX] * 3
    body.add_geom(**kw)


def _obstacle_geoms(m: mujoco.MjModel, name: str) -> np.ndarray:
    """Geom ids of ``m``'s obstacle body; raises :class:`SlotError` on a kind the slots do not cover."""
    geoms = obstacle_geom_ids(m)
    if (m.body_weldid[m.geom_bodyid[geoms]] != 0).any():
        raise SlotError(f"{name}: the {OBSTACLE_BODY!r} body moves; slots need static obstacles")
    bad = sorted({mujoco.mjtGeom(t).name for t in m.geom_type[geoms] if int(t) not in KINDS})
    if bad:
        raise SlotError(f"{name}: obstacle geom types {bad} have no warp slots (mesh, box, hfield only)")
    return geoms


def _cell_bodies(m: mujoco.MjModel) -> list[str]:
    """Names of the obstacle body's children (its cells, ``add_obstacles_to_spec(cells=...)``), in order."""
    root = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, OBSTACLE_BODY)
    if root < 0:
        return []
    return [m.body(b).name for b in range(root + 1, m.nbody) if m.body_parentid[b] == root]


def _shared_props(table: Sequence[mujoco.MjModel]) -> dict[str, np.ndarray]:
    """The contact properties of the table's obstacle geoms, checked equal for all of them."""
    props: dict[str, np.ndarray] = {}
    for i, m in enumerate(table):
        geoms = _obstacle_geoms(m, f"table model {i}")
        for name in SHARED_PROPS:
            vals = getattr(m, name)[geoms]
            if len(vals) == 0:
                continue
            ref = props.setdefault(name, vals[0].copy())
            odd = np.flatnonzero((vals != ref).reshape(len(vals), -1).any(axis=1))
            if len(odd):
                v = vals[odd[0]]
                raise SlotError(
                    f"table model {i}: obstacle {name} {v.tolist()} differs from {ref.tolist()}; warp slots "
                    "give every world one set of obstacle contact properties (mujoco_warp cannot vary contype, "
                    "conaffinity, condim or priority per world; the others are not batched by the slots)"
                )
    return props


def _check_bodies(ref: mujoco.MjModel, model: mujoco.MjModel) -> None:
    names = [ref.body(i).name for i in range(ref.nbody)]
    got = [model.body(i).name for i in range(model.nbody)]
    if names != got:
        raise SlotError(f"slot model bodies {got} differ from the scene models' {names}")


def _geometry_key(m: mujoco.MjModel) -> str:
    """Hash of a model's obstacle geometry (pool members of one scene share it)."""
    h = hashlib.sha1()
    b = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, OBSTACLE_BODY)
    geoms = obstacle_geom_ids(m)
    if b >= 0:
        h.update(m.body_pos[b].tobytes() + m.body_quat[b].tobytes())
    for g in geoms:
        for arr in (m.geom_type[g], m.geom_size[g], m.geom_pos[g], m.geom_quat[g]):
            h.update(np.ascontiguousarray(arr).tobytes())
        if m.geom_type[g] == _MESH:
            h.update(_mesh_arrays(m, int(m.geom_dataid[g]))[0].tobytes())
        elif m.geom_type[g] == _HFIELD:
            h.update(_hfield_arrays(m, int(m.geom_dataid[g]))[1].tobytes())
    return h.hexdigest()


def _mesh_arrays(m: mujoco.MjModel, i: int) -> tuple[np.ndarray, np.ndarray]:
    v0, nv = m.mesh_vertadr[i], m.mesh_vertnum[i]
    f0, nf = m.mesh_faceadr[i], m.mesh_facenum[i]
    return m.mesh_vert[v0 : v0 + nv].copy(), m.mesh_face[f0 : f0 + nf].copy()


def _mesh_collision(m: mujoco.MjModel, i: int) -> list[np.ndarray]:
    """A mesh's compiled data the collision code reads: vertices, faces, offset, hull graph, polygons."""
    vert, face = _mesh_arrays(m, i)
    out = [vert, face, m.mesh_pos[i], m.mesh_quat[i], m.mesh_polynum[i : i + 1]]
    g = m.mesh_graphadr[i]
    if g >= 0:  # [numvert, numface, then 3 numvert + 6 numface ints]
        out.append(m.mesh_graph[g : g + 2 + 3 * m.mesh_graph[g] + 6 * m.mesh_graph[g + 1]])
    p0, pn = m.mesh_polyadr[i], m.mesh_polynum[i]
    out += [m.mesh_polyvertnum[p0 : p0 + pn], m.mesh_polynormal[p0 : p0 + pn]]
    return out


def _hfield_arrays(m: mujoco.MjModel, i: int) -> tuple[tuple[int, int, list[float]], np.ndarray]:
    nrow, ncol = int(m.hfield_nrow[i]), int(m.hfield_ncol[i])
    a = m.hfield_adr[i]
    return (nrow, ncol, m.hfield_size[i].tolist()), m.hfield_data[a : a + nrow * ncol].copy()


class _Assets:
    """The union of the table's meshes and height fields (deduplicated by content), added in one order."""

    def __init__(self) -> None:
        self.meshes: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.hfields: dict[str, tuple[tuple[int, int, list[float]], np.ndarray]] = {}
        self._names: dict[bytes, str] = {}

    @property
    def mesh_names(self) -> list[str]:
        return list(self.meshes)

    @property
    def hfield_names(self) -> list[str]:
        return list(self.hfields)

    def mesh(self, m: mujoco.MjModel, i: int) -> str:
        vert, face = _mesh_arrays(m, i)
        key = b"m" + vert.tobytes() + face.tobytes()
        if key not in self._names:
            self._names[key] = name = f"slot_mesh_{len(self.meshes)}"
            self.meshes[name] = (vert, face)
        return self._names[key]

    def hfield(self, m: mujoco.MjModel, i: int) -> str:
        shape, data = _hfield_arrays(m, i)
        key = b"h" + repr(shape).encode() + data.tobytes()
        if key not in self._names:
            self._names[key] = name = f"slot_hfield_{len(self.hfields)}"
            self.hfields[name] = (shape, data)
        return self._names[key]

    def add_to(self, spec: mujoco.MjSpec) -> None:
        for name, (vert, face) in self.meshes.items():
            spec.add_mesh(name=name, uservert=vert.ravel().tolist(), userface=face.ravel().tolist())
        for name, ((nrow, ncol, size), data) in self.hfields.items():
            spec.add_hfield(name=name, nrow=nrow, ncol=ncol, size=size, userdata=data.tolist())

    def check_same(self, a: mujoco.MjModel, b: mujoco.MjModel) -> None:
        """The catalogue and the slot model compiled every asset to the same data (vertices, offset, convex hull
        graph and polygons: what the narrow phase reads), and height fields to their source data."""
        for name, (vert, _) in self.meshes.items():
            ia, ib = a.mesh(name).id, b.mesh(name).id
            same = [np.array_equal(x, y) for x, y in zip(_mesh_collision(a, ia), _mesh_collision(b, ib), strict=True)]
            if not all(same) or _mesh_arrays(a, ia)[0].shape != vert.shape or a.mesh_graphadr[ia] < 0:
                raise SlotError(f"mesh {name} compiled differently in the catalogue and the slot model")
        for name, (shape, data) in self.hfields.items():
            (sa, da), (sb, db) = _hfield_arrays(a, a.hfield(name).id), _hfield_arrays(b, b.hfield(name).id)
            if not (sa == sb == shape and np.array_equal(da, db) and np.allclose(da, data, rtol=0, atol=1e-6)):
                raise SlotError(f"height field {name} did not compile to its source data")


def _catalogue_rows(cat: mujoco.MjModel, model: mujoco.MjModel, parked_mesh: int | None) -> dict[str, np.ndarray]:
    """Every catalogue geom's rows, data ids mapped to ``model``'s assets; the parked mesh gets data id -1."""
    d = mujoco.MjData(cat)
    mujoco.mj_kinematics(cat, d)
    dataid = cat.geom_dataid.copy()
    for g in range(cat.ngeom):
        if cat.geom_type[g] == _MESH:
            dataid[g] = model.mesh(cat.mesh(dataid[g]).name).id
        elif cat.geom_type[g] == _HFIELD:
            dataid[g] = model.hfield(cat.hfield(dataid[g]).name).id
    if parked_mesh is not None:
        dataid[parked_mesh] = -1  # absent from the world (mujoco_warp skips it in the broadphase)
    return {
        "geom_dataid": dataid,
        "geom_pos": cat.geom_pos.copy(),
        "geom_quat": cat.geom_quat.copy(),
        "geom_size": cat.geom_size.copy(),
        "geom_aabb": cat.geom_aabb.reshape(-1, 2, 3).copy(),
        "geom_rbound": cat.geom_rbound.copy(),
        "geom_xpos": d.geom_xpos.copy(),
        "geom_xmat": d.geom_xmat.reshape(-1, 3, 3).copy(),
    }


class SlotWriter:
    """Writes table models' slot rows and robot physics into mujoco_warp's per-world arrays (torch views:
    in-place, so captured graphs stay valid)."""

    def __init__(self, slots: SlotTable, model_views: dict[str, torch.Tensor], data_views: dict[str, torch.Tensor]):
        self.slots = slots
        self.views = {**model_views, **data_views}
        dev = next(iter(self.views.values())).device
        self.geoms = torch.as_tensor(slots.geoms, device=dev)
        self.rows = torch.as_tensor(slots.rows, device=dev)
        self.catalogue = {k: torch.as_tensor(v, device=dev).to(self.views[k].dtype) for k, v in slots.catalogue.items()}
        self.robot = {
            f: torch.stack([torch.as_tensor(getattr(m, f)) for m in slots.table]).to(dev, self.views[f].dtype)
            for f in ROBOT_FIELDS
        }

    def write(self, env_ids: torch.Tensor, model_ids: torch.Tensor) -> None:
        """World ``env_ids[k]`` gets table model ``model_ids[k]``'s obstacles and robot physics."""
        ids, mids = env_ids[:, None], model_ids
        rows = self.rows[mids]  # (k, S) catalogue rows
        for name, cat in self.catalogue.items():
            self.views[name][ids, self.geoms[None, :]] = cat[rows]
        for name, values in self.robot.items():
            self.views[name][env_ids] = values[mids]
