"""Per-world scenes on ``sim=warp`` (``cat.envs.sim.warp_slots``): one slot model, per-world obstacle rows.

Real mujoco_warp on the Warp CPU device, tiny sizes (2-4 worlds). Scenes as in ``tests/test_per_world.py``:
side-crouch (free around ``SPOT``), hurdle-pass (its side wall at ``SPOT``) and hurdle-crouch (2 convex parts,
so one of the 3 mesh slots is absent from its worlds); a procedural scene for box and height-field slots.

Parity with the MuJoCo C per-world path (``MujocoBackend.set_model_table``): same table, same initial states,
same PD targets, converged solver in both (``iterations=100, ls_iterations=50, tolerance=1e-7``, as
``tests/test_sim_parity.py`` does, so the comparison does not hinge on where an unconverged solve stops).
Tolerances ``QPOS_ATOL`` / ``QVEL_ATOL`` after every control step: what is left is float32 (warp) against
float64 (C), amplified by contacts that come and go (two worlds lean a hand on the wall). Measured over 25 control
steps: qpos 1.8e-3, qvel 0.23 (a wrist at the instant its contact breaks). Contact lists are compared where
both backends see the same state (after a reset from one state): identical geom pairs and counts.
"""

from __future__ import annotations

import copy
import logging
from collections import Counter

import mujoco
import numpy as np
import pytest
import torch

from cat.envs.config import DomainRandCfg, EnvCfg
from cat.envs.robot import home_qpos
from cat.envs.scene import COLLISION_SENSOR
from cat.envs.scene_models import WorldModels
from cat.envs.scene_set import SceneSet, scene_fields
from cat.envs.sim.mujoco_backend import MujocoBackend
from cat.envs.sim.warp_backend import WarpBackend
from cat.envs.sim.warp_slots import PARK_Z, SlotError, SlotTable
from cat.envs.traversal_env import TraversalEnv
from cat.terrain import make_procedural, typical_variants
from cat.terrain.mujoco_export import obstacle_geom_ids

KINDS = ("side-crouch", "hurdle-pass", "hurdle-crouch")  # 3, 3 and 2 convex parts
FREE, WALL, CROUCH = 0, 1, 2
SPOT = (0.4, 0.6)  # xy inside hurdle-pass's side wall, free in side-crouch
LEAN = (0.5, 0.2)  # xy where the G1's left hand presses ~1 cm into hurdle-pass's side wall
STEPS = 25
QPOS_ATOL, QVEL_ATOL = 5e-3, 0.5
PLAIN_ATOL = 1e-4  # slot world vs mujoco_warp on its own scene model: same float32 physics, other geom order
DEEP_CONTACT = 0.05  # m; mujoco_warp 4.0 reports limbs beside a tall height-field wall ~1 m deep (MuJoCo C: mm),
# and from there both runs are chaotic: parity is compared up to the first such contact (docs/scenes.md)

log = logging.getLogger(__name__)


@pytest.fixture(scope="module")
def scenes():
    return [typical_variants(k, 1, 0)[0] for k in KINDS]


@pytest.fixture(scope="module")
def world_models(scenes, robot_cfg):
    """Scene models with a pool of 2 randomised members each (model id = scene * 2 + member)."""
    dr = DomainRandCfg()
    dr.enabled, dr.pool_size = True, 2
    wm = WorldModels.build(robot_cfg, scenes, dr, seed=0)
    for m in wm.models:
        m.opt.iterations, m.opt.ls_iterations, m.opt.tolerance = 100, 50, 1e-7
    return wm


@pytest.fixture(scope="module")
def slots(world_models, robot_cfg):
    st = SlotTable.build(world_models.models, world_models.compose)
    st.model.opt.iterations, st.model.opt.ls_iterations, st.model.opt.tolerance = 100, 50, 1e-7
    return st


def c_contacts(m: mujoco.MjModel, qpos: np.ndarray) -> Counter:
    """(robot geom, obstacle part index) of every robot-obstacle contact of ``m`` at ``qpos``."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    part = {int(g): k for k, g in enumerate(obstacle_geom_ids(m))}
    return Counter((int(c.geom[0]), part[int(c.geom[1])]) for c in d.contact[: d.ncon] if int(c.geom[1]) in part)


def warp_contacts(sim: WarpBackend, world: int) -> Counter:
    """The same for world ``world`` of a slot backend (slot k of a mesh-only table = the scene's part k)."""
    n = int(sim.d.nacon.numpy()[0])
    geom, wid = sim.d.contact.geom.numpy()[:n], sim.d.contact.worldid.numpy()[:n]
    part = {int(g): k for k, g in enumerate(sim.slots.geoms)}
    return Counter((int(g1), part[int(g2)]) for (g1, g2), w in zip(geom, wid, strict=True) if w == world and g2 in part)


def test_slot_table_picks_each_scenes_geometry(world_models, slots):
    models = world_models.models
    assert slots.counts == {"mesh": 3, "box": 0, "hfield": 0}  # the most parts any scene has
    assert np.array_equal(slots.rows[0], slots.rows[1])  # pool members share their scene's rows
    crouch = slots.catalogue["geom_dataid"][slots.rows[2 * CROUCH]]
    assert (crouch[:2] >= 0).all() and crouch[2] == -1  # 2 parts: the third mesh slot is absent
    assert slots.catalogue["geom_xpos"][slots.rows[2 * CROUCH][2], 2] == PARK_Z
    sm = slots.model
    for t, m in enumerate(models):  # each part lands where the scene model has it (world vertices)
        d = mujoco.MjData(m)
        mujoco.mj_kinematics(m, d)
        for k, g in enumerate(obstacle_geom_ids(m)):
            c = slots.rows[t, k]
            i, j = m.geom_dataid[g], slots.catalogue["geom_dataid"][c]
            v = m.mesh_vert[m.mesh_vertadr[i] : m.mesh_vertadr[i] + m.mesh_vertnum[i]]
            u = sm.mesh_vert[sm.mesh_vertadr[j] : sm.mesh_vertadr[j] + sm.mesh_vertnum[j]]
            world_v = d.geom_xpos[g] + v @ d.geom_xmat[g].reshape(3, 3).T
            world_u = slots.catalogue["geom_xpos"][c] + u @ slots.catalogue["geom_xmat"][c].T
            np.testing.assert_allclose(world_u, world_v, atol=1e-7)
            assert sm.mesh_graphadr[j] >= 0 and sm.mesh_polynum[j] == m.mesh_polynum[i]  # hull for the narrow phase
    ref = obstacle_geom_ids(models[0])[0]
    for name in ("geom_conaffinity", "geom_solref", "geom_friction"):  # contact properties as the scenes'
        assert np.array_equal(getattr(sm, name)[slots.geoms], np.repeat(getattr(models[0], name)[ref][None], 3, 0))


def test_obstacle_props_must_agree_across_scenes(world_models, robot_cfg):
    odd = [copy.copy(m) for m in world_models.models[:3]]
    odd[2].geom_priority[obstacle_geom_ids(odd[2])] += 1  # not batched by mujoco_warp
    with pytest.raises(SlotError, match="table model 2: obstacle geom_priority"):
        SlotTable.build(odd, world_models.compose)


def test_parity_with_the_mujoco_per_world_path(world_models, slots, robot_cfg):
    models, n, dec = world_models.models, 4, robot_cfg.decimation
    c = MujocoBackend(models[0], n, dec, nthread=1, max_sensors=(COLLISION_SENSOR,))
    c.set_model_table(models)
    w = WarpBackend(models[0], n, dec, device="cpu", max_sensors=(COLLISION_SENSOR,), slots=slots)
    mids = torch.tensor([2 * WALL + 1, 2 * FREE, 2 * WALL, 2 * CROUCH + 1])  # pool members differ in kp and mass
    for b in (c, w):
        b.assign_models(torch.arange(n), mids)
    assert w.model_ids.tolist() == c.model_ids.tolist() == mids.tolist()
    qpos = torch.tensor(home_qpos(robot_cfg), dtype=torch.float64).repeat(n, 1)
    qpos[:3, :2] = torch.tensor(LEAN, dtype=torch.float64)  # walls in worlds 0 and 2, nothing in world 1
    qvel = torch.zeros(n, models[0].nv, dtype=torch.float64)

    def same_contacts(q: torch.Tensor) -> list[int]:
        for b in (c, w):
            b.reset(torch.arange(n), q, qvel)
        got = [warp_contacts(w, i) for i in range(n)]
        assert got == [c_contacts(models[m], q[i].numpy()) for i, m in enumerate(mids.tolist())]
        torch.testing.assert_close(w.sensordata.double(), c.sensordata, rtol=1e-3, atol=1e-3)  # float32
        return [sum(g.values()) for g in got]

    assert same_contacts(qpos) == [2, 0, 2, 0]
    rng = torch.Generator().manual_seed(0)
    err_q = err_v = 0.0
    for _ in range(STEPS):
        ctrl = qpos[:, 7:] + 0.1 * torch.rand(n, robot_cfg.num_joints, generator=rng, dtype=torch.float64)
        c.step(ctrl)
        w.step(ctrl)
        err_q = max(err_q, (w.qpos.double() - c.qpos).abs().max().item())
        err_v = max(err_v, (w.qvel.double() - c.qvel).abs().max().item())
    log.info("warp slots vs MuJoCo C per-world, %d control steps: max |dqpos| %.2e, |dqvel| %.2e", STEPS, err_q, err_v)
    assert err_q < QPOS_ATOL and err_v < QVEL_ATOL, (err_q, err_v)
    same_contacts(w.qpos.double().clone())  # from warp's final state: the same contacts in both


def test_worlds_touch_only_their_scene_and_follow_scene_changes(scenes):
    """Env level (``sim=warp sim.per_world_scenes=true``): two worlds at the same spot, one per scene, then
    swapped at reset; contacts, the collision flag, the field and the snapshot's model ids follow."""
    cfg = EnvCfg(num_envs=2)
    cfg.curriculum.enabled = False
    two = scenes[:2]
    fields = [scene_fields(s, None, None) for s in two]
    env = TraversalEnv(cfg, sim="warp", scenes=SceneSet(two, fields, 2, per_world=True), seed=0)
    assert env.sim.slots.counts["mesh"] == 3

    def place(scene_ids: list[int]) -> None:
        start = torch.tensor([SPOT] * 2, dtype=torch.float32)
        goal = torch.tensor([[2.0, 0.0, 0.75]] * 2)
        env.reset_to(torch.arange(2), start, torch.zeros(2), goal, torch.tensor(scene_ids), torch.zeros(2).long())

    place([FREE, WALL])  # world 0's mesh slots hold side-crouch's parts, world 1's the wall at the same spot
    contact = env.sim.sensor(COLLISION_SENSOR)[:, 0]
    assert contact[0] == 0 and contact[1] > 0
    assert not warp_contacts(env.sim, 0) and warp_contacts(env.sim, 1)
    assert env.state.collision.tolist() == [False, True]
    assert env.field.sdf[0].min() > 0.2 and env.field.sdf[1].min() < 0.0
    snap = env.get_state()
    assert snap["sim"]["model_ids"].tolist() == [FREE, WALL]

    place([WALL, FREE])  # scene change at reset: rows rewritten, the other way round
    contact = env.sim.sensor(COLLISION_SENSOR)[:, 0]
    assert contact[0] > 0 and contact[1] == 0
    assert warp_contacts(env.sim, 0) and not warp_contacts(env.sim, 1)
    assert env.state.collision.tolist() == [True, False]
    assert env.field.sdf[0].min() < 0.0 and env.field.sdf[1].min() > 0.2
    assert env.sim.model_ids.tolist() == [WALL, FREE]

    env.set_state(snap)  # the snapshot puts each world back on its scene's rows
    assert env.sim.model_ids.tolist() == [FREE, WALL]
    env.sim.reset(torch.arange(2), env.sim.qpos.double().clone(), env.sim.qvel.double().clone())
    contact = env.sim.sensor(COLLISION_SENSOR)[:, 0]
    assert contact[0] == 0 and contact[1] > 0


def obstacle_kinds(m: mujoco.MjModel, qpos: np.ndarray) -> list[int]:
    """Geom types of the obstacles ``m``'s robot touches at ``qpos`` (MuJoCo C)."""
    d = mujoco.MjData(m)
    d.qpos[:] = qpos
    mujoco.mj_forward(m, d)
    obstacle = set(obstacle_geom_ids(m).tolist())
    return sorted(int(m.geom_type[g]) for c in d.contact[: d.ncon] for g in c.geom if int(g) in obstacle)


def test_box_and_height_field_slots_step_like_the_scene_model(robot_cfg):
    """A procedural scene (height-field tiles and boxes) next to a typical one (meshes): each slot world steps
    like mujoco_warp on that world's own scene model (float32 summation order aside: ``PLAIN_ATOL``), and the
    typical world, whose box and height-field slots are parked, touches only its wall."""
    from cat.envs.scene import model_composer
    from cat.envs.scene_models import build_scene_models

    scenes = [make_procedural(0.3, 1), typical_variants("hurdle-pass", 1, 0)[0]]
    models = build_scene_models(robot_cfg, scenes)
    slots = SlotTable.build(models, model_composer(robot_cfg))
    assert slots.counts["box"] > 0 and slots.counts["hfield"] > 0 and slots.counts["mesh"] == 3
    dec, kw = robot_cfg.decimation, dict(device="cpu", max_sensors=(COLLISION_SENSOR,), nconmax=96, njmax=384)
    qpos = torch.tensor(home_qpos(robot_cfg), dtype=torch.float64).repeat(3, 1)
    qpos[:, :2] = torch.tensor([(1.4, -1.2), (1.1, -2.8), LEAN], dtype=torch.float64)
    qvel = torch.zeros(3, models[0].nv, dtype=torch.float64)
    hfield, box = int(mujoco.mjtGeom.mjGEOM_HFIELD), int(mujoco.mjtGeom.mjGEOM_BOX)
    for i in range(2):  # both obstacle kinds touched, lightly
        assert {hfield, box} <= set(obstacle_kinds(models[0], qpos[i].numpy()))
    w = WarpBackend(models[0], 3, dec, slots=slots, **kw)
    w.assign_models(torch.arange(3), torch.tensor([0, 0, 1]))
    plain = [WarpBackend(models[0], 2, dec, **kw), WarpBackend(models[1], 1, dec, **kw)]
    parts = [slice(0, 2), slice(2, 3)]
    w.reset(torch.arange(3), qpos, qvel)
    for p, rows in zip(plain, parts, strict=True):
        p.reset(torch.arange(rows.stop - rows.start), qpos[rows], qvel[rows])
    assert [len(obstacle_kinds(models[m], qpos[i].numpy())) for i, m in enumerate((0, 0, 1))] == w.sensor(
        COLLISION_SENSOR
    )[:, 0].tolist()  # one contact per touched geom pair here: counts as MuJoCo C's
    rng = torch.Generator().manual_seed(0)
    err, compared = 0.0, 0
    for _ in range(10):
        ctrl = qpos[:, 7:] + 0.1 * torch.rand(3, robot_cfg.num_joints, generator=rng, dtype=torch.float64)
        w.step(ctrl)
        for p, rows in zip(plain, parts, strict=True):
            p.step(ctrl[rows])
        if max(_deepest_contact(b) for b in (w, *plain)) > DEEP_CONTACT:
            break  # mujoco_warp's deep height-field contacts (see DEEP_CONTACT): chaotic in both, not comparable
        for p, rows in zip(plain, parts, strict=True):
            assert torch.equal(w.sensor(COLLISION_SENSOR)[rows], p.sensor(COLLISION_SENSOR))
            err = max(err, (w.qpos[rows] - p.qpos).abs().max().item())
        compared += 1
    log.info("box / height-field slots vs plain mujoco_warp, %d control steps: max |dqpos| %.2e", compared, err)
    assert compared >= 4 and err < PLAIN_ATOL


def _deepest_contact(backend: WarpBackend) -> float:
    """Deepest penetration [m] among a mujoco_warp backend's contacts of its last step."""
    n = int(backend.d.nacon.numpy()[0])
    return float(-backend.d.contact.dist.numpy()[:n].min()) if n else 0.0
