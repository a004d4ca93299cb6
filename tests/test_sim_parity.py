"""Parity of the two physics backends: ``MujocoBackend`` (MuJoCo C, float64) vs ``WarpBackend(device="cpu")``.

Same model, same initial states (home pose and small perturbations of it), 50 control steps (decimation 4,
1 s) of the same smooth pseudo-random PD targets around the default pose; qpos / qvel / sensordata are
compared after every control step. Two scenarios: 3 worlds on the floor, and 2 worlds of which one stands
with its hands pressed 1 cm into an obstacle box and an obstacle convex mesh (contact sensor nonzero).

1. Converged solver (``iterations=100, ls_iterations=50, tolerance=1e-7`` in both backends): warp must match
   C to ``TIGHT`` (qpos 3e-4, qvel 2e-2, position sensors 3e-4, velocity sensors 5e-3, accelerometers 5e-2,
   contact counts exact). What is left is float32 (warp) vs float64 (C) rounding, amplified by contact
   dynamics. Measured: floor qpos 6e-6 / qvel 3e-4 / accelerometer 1e-3; obstacle qpos 7e-5 / qvel 4e-3 /
   accelerometer 6e-3; counts identical.
2. The model's own solver (5 Newton iterations, 8 line-search iterations): the contact solve does not
   converge in 5 iterations, so the result depends on the starting point: mujoco_warp carries the warmstart
   across ``step`` calls, ``mujoco.rollout`` (``MujocoBackend``) restarts it from zero, and float32 perturbs
   it. MuJoCo C against itself (``MujocoBackend`` vs a plain ``mj_step`` loop, which also carries the
   warmstart) differs by up to ~5 mm in qpos and ~0.6 rad/s in qvel (light ankle / wrist joints) within 1 s;
   that C-vs-C spread is the yardstick: per quantity, max and RMS error of warp vs ``MujocoBackend`` must be
   <= 4x the spread + a float32 floor, and under absolute caps (``CAP``). Measured (max, warp / C-vs-C):
   floor qpos 6.3e-3 / 5.0e-3, qvel 0.49 / 0.63; obstacle qpos 1.6e-2 / 2.0e-2, qvel 2.2 / 2.0.

The model is the env model with an ``obstacles`` body (a box and a convex mesh) 5 m from the origin:
worlds at the origin never touch it.
"""

from __future__ import annotations

import copy
import logging
import os

import mujoco
import numpy as np
import pytest
import torch
import warp as wp

from cat.envs.robot import OBSTACLE_BIT, OBSTACLE_BODY, home_qpos
from cat.envs.scene import COLLISION_SENSOR, build_env_model
from cat.envs.sim.mujoco_backend import MujocoBackend
from cat.envs.sim.warp_backend import WarpBackend, resolve_device

log = logging.getLogger(__name__)

WARP_DEVICE = os.environ.get("CAT_WARP_TEST_DEVICE", "cpu")  # cuda:0 on a lent GPU (scripts/gpu/check.sh)
BITWISE = not WARP_DEVICE.startswith("cuda")
"""Warp's CPU device runs kernels in a fixed order, so equal launches give equal bits. On CUDA mujoco_warp
accumulates with float atomics whose order varies between launches: the last bit differs (H200, 2026-12-04:
max 1.5e-8 on 20 of 72 state values after 10 steps, graph replay against eager launches)."""

STEPS = 50
OBSTACLE_X = 5.0


def add_obstacles(spec: mujoco.MjSpec) -> None:
    """A wall box 1 cm into the left hand and a convex wedge mesh 1 cm into the right hand (robot at x=5)."""
    body = spec.worldbody.add_body(name=OBSTACLE_BODY, pos=[OBSTACLE_X, 0.0, 0.0])
    common = {"contype": 0, "conaffinity": OBSTACLE_BIT, "condim": 3}
    body.add_geom(name="wall", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0.354, 0.75], size=[0.2, 0.05, 0.35], **common)
    wedge = np.array(
        [[-0.2, 0, 0.4], [0.2, 0, 0.4], [-0.2, 0, 1.1], [0.2, 0, 1.1], [-0.2, -0.1, 0.4], [0.2, -0.1, 0.4]]
    )
    wedge[:, 1] -= 0.304  # inner face 1 cm into the right hand (its outer side is at y = -0.314)
    spec.add_mesh(name="wedge", uservert=wedge.reshape(-1).tolist())
    body.add_geom(name="wedge", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="wedge", **common)


@pytest.fixture(scope="module")
def model(robot_cfg) -> mujoco.MjModel:
    return build_env_model(robot_cfg, add_obstacles)


def converged(model: mujoco.MjModel) -> mujoco.MjModel:
    """Copy of ``model`` whose constraint solver converges (runtime options: no warp recompile)."""
    m = copy.copy(model)
    m.opt.iterations, m.opt.ls_iterations, m.opt.tolerance = 100, 50, 1e-7
    return m


def initial_states(cfg, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """World 0: home pose at rest; others: joints +-0.05 rad and a small base twist."""
    rng = np.random.default_rng(seed)
    q0 = home_qpos(cfg)
    qpos = np.tile(q0, (n, 1))
    qvel = np.zeros((n, 6 + cfg.num_joints))
    qpos[1:, 7:] += rng.uniform(-0.05, 0.05, (n - 1, cfg.num_joints))
    qvel[1:, :6] = rng.uniform(-0.05, 0.05, (n - 1, 6))
    return qpos, qvel


def actions(cfg, n: int, steps: int, seed: int = 1) -> np.ndarray:
    """(steps, n, nu) PD targets: default pose + sum of two sines per joint (amplitude <= 0.09 rad)."""
    rng = np.random.default_rng(seed)
    t = np.arange(steps)[:, None, None] * cfg.control_dt
    freq = rng.uniform(0.5, 2.0, (2, n, cfg.num_joints))
    phase = rng.uniform(0, 2 * np.pi, (2, n, cfg.num_joints))
    wave = 0.06 * np.sin(2 * np.pi * freq[0] * t + phase[0]) + 0.03 * np.sin(2 * np.pi * freq[1] * t + phase[1])
    return cfg.default_joint_pos + wave


def rollout(backend, qpos, qvel, ctrl) -> dict[str, np.ndarray]:
    backend.reset(torch.arange(len(qpos)), torch.as_tensor(qpos), torch.as_tensor(qvel))
    out = {"qpos": [], "qvel": [], "sens": [], "sens0": backend.sensordata.double().cpu().numpy().copy()}
    for u in ctrl:
        backend.step(torch.as_tensor(u, dtype=torch.float32))
        out["qpos"].append(backend.qpos.double().cpu().numpy().copy())
        out["qvel"].append(backend.qvel.double().cpu().numpy().copy())
        out["sens"].append(backend.sensordata.double().cpu().numpy().copy())
    return {k: np.stack(v) for k, v in out.items()}


def mj_step_loop(model: mujoco.MjModel, qpos, qvel, ctrl, decimation: int) -> dict[str, np.ndarray]:
    """The same rollout with a plain ``mj_step`` loop in MuJoCo C (warmstart carried over, as in warp)."""
    d = mujoco.MjData(model)
    steps, n = ctrl.shape[:2]
    out = {"qpos": np.zeros((steps, n, model.nq)), "qvel": np.zeros((steps, n, model.nv))}
    out["sens"] = np.zeros((steps, n, model.nsensordata))
    for w in range(n):
        mujoco.mj_resetData(model, d)
        d.qpos[:], d.qvel[:] = qpos[w], qvel[w]
        for k in range(steps):
            d.ctrl[:] = ctrl[k, w].astype(np.float32)
            mujoco.mj_step(model, d, nstep=decimation)
            out["qpos"][k, w], out["qvel"][k, w], out["sens"][k, w] = d.qpos, d.qvel, d.sensordata
    return out


def sensor_columns(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """sensordata columns grouped by kind (position-like, velocity-like, accelerometer, contact count)."""
    groups: dict[str, list[int]] = {"pos": [], "vel": [], "acc": [], "count": []}
    t = mujoco.mjtSensor
    kind = {
        int(t.mjSENS_ACCELEROMETER): "acc",
        int(t.mjSENS_CONTACT): "count",
        int(t.mjSENS_FRAMEPOS): "pos",
        int(t.mjSENS_FRAMEQUAT): "pos",
        int(t.mjSENS_FRAMEZAXIS): "pos",
    }
    for i in range(model.nsensor):
        adr, dim = model.sensor_adr[i], model.sensor_dim[i]
        groups[kind.get(int(model.sensor_type[i]), "vel")].extend(range(adr, adr + dim))
    return {k: np.array(v, dtype=int) for k, v in groups.items()}


TIGHT = {"qpos": 3e-4, "qvel": 2e-2, "pos": 3e-4, "vel": 5e-3, "acc": 5e-2, "count": 0.0}
# float32-level floors and absolute caps (max, RMS) for the model's own (unconverged) solver
FLOOR = {"qpos": 1e-4, "qvel": 1e-2, "pos": 1e-4, "vel": 1e-2, "acc": 0.1, "count": 1.0}
CAP = {
    "qpos": (0.05, 5e-3),
    "qvel": (4.0, 0.2),
    "pos": (0.05, 5e-3),
    "vel": (0.5, 0.05),
    "acc": (5.0, 0.5),
    "count": (5.0, 0.8),
}


def errors(model, a: dict, b: dict) -> dict[str, tuple[float, float]]:
    """(max, RMS) abs difference per quantity."""
    cols = sensor_columns(model)
    diffs = {"qpos": a["qpos"] - b["qpos"], "qvel": a["qvel"] - b["qvel"]}
    diffs.update({g: a["sens"][..., c] - b["sens"][..., c] for g, c in cols.items()})
    return {k: (float(np.abs(v).max()), float(np.sqrt(np.mean(v**2)))) for k, v in diffs.items()}


def fmt(err: dict) -> dict[str, str]:
    return {k: f"{v[0]:.2g}/{v[1]:.2g}" for k, v in err.items()}


def run_scenario(model, cfg, scenario: str):
    """(MujocoBackend, WarpBackend, mj_step loop) trajectories and the initial state of ``scenario``."""
    n = 3 if scenario == "floor" else 2
    qpos, qvel = initial_states(cfg, n)
    if scenario == "obstacle":
        qpos[0, 0] = OBSTACLE_X  # world 0 between the wall and the wedge, both hands pressed 1 cm in
    ctrl = actions(cfg, n, STEPS)
    ref = rollout(MujocoBackend(model, n, cfg.decimation), qpos, qvel, ctrl)
    warp = WarpBackend(model, n, cfg.decimation, device=WARP_DEVICE)
    got = rollout(warp, qpos, qvel, ctrl)
    warp.check_overflow()
    assert (got["qpos"][:, :, 2] > 0.6).all()  # the robots stand: a fall would make the comparison moot
    if scenario == "obstacle":
        adr = model.sensor(COLLISION_SENSOR).adr[0]
        for out in (ref, got):
            assert out["sens0"][0, adr] == 4  # both hands, 2 contacts each (box: primitive, wedge: convex mesh)
            assert (out["sens"][:, 1, adr] == 0).all()  # world 1 is 5 m away
            assert (out["sens"][:, 0, adr] > 0).any()
    return ref, got, mj_step_loop(model, qpos, qvel, ctrl, cfg.decimation)


def test_cuda_request_without_gpu_names_the_fix():
    if torch.cuda.is_available():
        pytest.skip("a GPU is present")
    with pytest.raises(RuntimeError, match="device='cpu'"):
        resolve_device("cuda")


def test_graph_replay_matches_eager_launches(model, robot_cfg):
    """Captured step / forward (graph replay) == launching mujoco_warp eagerly (bitwise on Warp's CPU device)."""
    n = 2
    qpos, qvel = initial_states(robot_cfg, n)
    qpos[0, 0] = OBSTACLE_X  # contacts with the box and the mesh
    ctrl = torch.as_tensor(actions(robot_cfg, n, 10), dtype=torch.float32)
    backends = [WarpBackend(model, n, robot_cfg.decimation, device=WARP_DEVICE, graph=g) for g in (True, False)]
    assert backends[0]._step_graph is not None and backends[1]._step_graph is None
    qpos, qvel = torch.as_tensor(qpos), torch.as_tensor(qvel)
    for k, u in enumerate(ctrl):
        for b in backends:
            if k == 0:
                b.reset(torch.arange(n), qpos, qvel)
            if k == 5:  # a subset reset runs the captured forward pass
                b.reset(torch.tensor([1]), qpos[1:], qvel[1:])
            b.step(u)
        for ta, tb in zip(state(backends[0]), state(backends[1]), strict=True):
            assert_same(ta, tb)


@pytest.mark.parametrize("scenario", ["floor", "obstacle"])
def test_parity_converged_solver(model, robot_cfg, scenario):
    m = converged(model)
    ref, got, _ = run_scenario(m, robot_cfg, scenario)
    err = errors(m, ref, got)
    log.info("%s, converged solver: warp vs C (max/rms) %s", scenario, fmt(err))
    for k, (e_max, _) in err.items():
        assert e_max <= TIGHT[k], f"{k}: max abs error {e_max:.3g} > {TIGHT[k]}"
    # same contacts at reset, same sensors
    cols = sensor_columns(m)
    np.testing.assert_array_equal(got["sens0"][:, cols["count"]], ref["sens0"][:, cols["count"]])
    np.testing.assert_allclose(got["sens0"], ref["sens0"], atol=1e-4, rtol=1e-4)


@pytest.mark.parametrize("scenario", ["floor", "obstacle"])
def test_parity_model_solver(model, robot_cfg, scenario):
    ref, got, c_loop = run_scenario(model, robot_cfg, scenario)
    err, spread = errors(model, ref, got), errors(model, ref, c_loop)
    log.info("%s, model solver: warp vs C %s", scenario, fmt(err))
    log.info("%s, model solver: C vs C    %s", scenario, fmt(spread))
    for k, (e_max, e_rms) in err.items():
        s_max, s_rms = spread[k]
        assert e_max <= min(4 * s_max + FLOOR[k], CAP[k][0]), f"{k}: max err {e_max:.3g}, C-vs-C {s_max:.3g}"
        assert e_rms <= min(4 * s_rms + FLOOR[k], CAP[k][1]), f"{k}: rms err {e_rms:.3g}, C-vs-C {s_rms:.3g}"


def test_reset_subset_leaves_other_worlds_untouched(model, robot_cfg):
    """reset(ids) == a fresh reset for those worlds (bitwise) and a no-op for the others (bitwise)."""
    n = 4
    qpos, qvel = initial_states(robot_cfg, n)
    ctrl = torch.as_tensor(actions(robot_cfg, n, 12), dtype=torch.float32)
    a, twin = (WarpBackend(model, n, robot_cfg.decimation, device=WARP_DEVICE) for _ in range(2))
    for backend in (a, twin):
        backend.reset(torch.arange(n), torch.as_tensor(qpos), torch.as_tensor(qvel))
        for u in ctrl[:6]:
            backend.step(u)
    keep, ids = torch.tensor([0, 2]), torch.tensor([1, 3])
    before = [t.clone() for t in (a.qpos, a.qvel, a.sensordata, wp_time(a))]

    new_qpos, new_qvel = initial_states(robot_cfg, 3, seed=5)
    new_qpos, new_qvel = torch.as_tensor(new_qpos[1:]), torch.as_tensor(new_qvel[1:])
    a.reset(ids, new_qpos, new_qvel)
    for t, t0 in zip((a.qpos, a.qvel, a.sensordata, wp_time(a)), before, strict=True):
        assert torch.equal(t[keep], t0[keep])
    assert (wp_time(a)[ids] == 0).all()
    torch.testing.assert_close(a.qpos[ids].cpu(), new_qpos.float())
    torch.testing.assert_close(a.qvel[ids].cpu(), new_qvel.float())

    # the reset worlds' sensors match MuJoCo C's mj_resetData + mj_forward on the same state
    ref = MujocoBackend(model, 2, robot_cfg.decimation)
    ref.reset(torch.arange(2), new_qpos, new_qvel)
    cols = sensor_columns(model)
    for group, tol in (("pos", 1e-4), ("vel", 1e-3), ("acc", 0.05), ("count", 0.0)):
        c = torch.as_tensor(cols[group])
        torch.testing.assert_close(a.sensordata[ids][:, c].double().cpu(), ref.sensordata[:, c], atol=tol, rtol=0)

    # a fresh backend reset to the same states: the reset worlds carry no hidden state over (warmstart, ...)
    fresh = WarpBackend(model, n, robot_cfg.decimation, device=WARP_DEVICE)
    fresh.reset(torch.arange(n), a.qpos.clone(), a.qvel.clone())
    assert_same(fresh.sensordata[ids], a.sensordata[ids])
    for u in ctrl[6:]:
        for backend in (a, twin, fresh):
            backend.step(u)
        for ta, tb, tc in zip(state(a), state(twin), state(fresh), strict=True):
            assert_same(ta[keep], tb[keep])  # kept worlds go on as if nothing happened
            assert_same(ta[ids], tc[ids])  # reset worlds behave as freshly reset ones


def assert_same(a: torch.Tensor, b: torch.Tensor) -> None:
    """Equal bits on Warp's CPU device; equal to float32 rounding on CUDA (see ``BITWISE``)."""
    if BITWISE:
        assert torch.equal(a, b)
    else:
        torch.testing.assert_close(a, b, atol=1e-6, rtol=1e-6)


def state(backend: WarpBackend) -> tuple[torch.Tensor, ...]:
    return backend.qpos, backend.qvel, backend.sensordata, wp_time(backend)


def wp_time(backend: WarpBackend) -> torch.Tensor:
    return wp.to_torch(backend.d.time)


def test_domain_randomisation_parity(model, robot_cfg):
    """Per-world gains and masses: warp follows MuJoCo C (converged solver) and differs from the default."""
    m, n = converged(model), 2
    qpos, qvel = initial_states(robot_cfg, n)
    ctrl = actions(robot_cfg, n, 25)
    ids = torch.tensor([0])
    kp = torch.as_tensor(robot_cfg.kp[None] * 0.8)
    kd = torch.as_tensor(robot_cfg.kd[None] * 1.5)
    scale = torch.ones(1, m.nbody, dtype=torch.float64)
    scale[0, 1:] = torch.linspace(0.9, 1.2, m.nbody - 1, dtype=torch.float64)
    outs = []
    for backend in (MujocoBackend(m, n, robot_cfg.decimation), WarpBackend(m, n, robot_cfg.decimation, "cpu")):
        backend.set_actuator_gains(ids, kp, kd)
        backend.set_body_mass_scale(ids, scale)
        outs.append(rollout(backend, qpos, qvel, ctrl))
    ref, got = outs
    err = errors(m, ref, got)
    log.info("randomised, converged solver: warp vs C (max/rms) %s", fmt(err))
    for k in ("qpos", "qvel", "pos"):
        assert err[k][0] <= TIGHT[k], f"{k}: max abs error {err[k][0]:.3g} > {TIGHT[k]}"
    plain = rollout(WarpBackend(m, n, robot_cfg.decimation, "cpu"), qpos, qvel, ctrl)
    assert np.abs(plain["qpos"][:, 0] - got["qpos"][:, 0]).max() > 10 * TIGHT["qpos"]  # world 0 changed
    np.testing.assert_array_equal(plain["qpos"][:, 1], got["qpos"][:, 1])  # world 1 did not


def test_mujoco_auto_reset_of_a_diverged_world_is_counted(model, robot_cfg):
    """A world sent off with a velocity MuJoCo rejects (> mjMAXVAL) is reset by MuJoCo inside the rollout (its
    clock jumps back to 0): ``auto_resets`` counts it, and the healthy worlds do not add to the count."""
    backend = MujocoBackend(model, 3, robot_cfg.decimation)
    qpos, qvel = initial_states(robot_cfg, 3, seed=2)
    qvel[1, 0] = 1e12  # world 1 diverges at its first substep
    backend.reset(torch.arange(3), torch.as_tensor(qpos), torch.as_tensor(qvel))
    ctrl = torch.as_tensor(actions(robot_cfg, 3, 1)[0])
    backend.step(ctrl)
    assert backend.auto_resets == 1
    for _ in range(3):
        backend.step(ctrl)
    assert backend.auto_resets == 1 and torch.isfinite(backend.qpos).all()
