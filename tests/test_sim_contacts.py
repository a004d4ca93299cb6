"""Robot-obstacle contacts count on every physics substep (both backends); warp buffer overflow raises.

Scenario: gravity off, the G1 held in its default pose glides along +x at 5 m/s past a thin vertical rod
(capsule, r 5 mm) whose side just touches the outer edge of its left arm: the touch lasts one physics
substep (5 ms), placed in the middle of a control step (4 substeps). The ground truth is the per-substep
contact sensor of the same simulator stepped one substep at a time.
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from cat.envs.robot import OBSTACLE_BIT, OBSTACLE_BODY, home_qpos
from cat.envs.scene import COLLISION_SENSOR, build_env_model
from cat.envs.sim import make_backend
from cat.envs.sim.mujoco_backend import MujocoBackend

SPEED = 5.0  # m/s along +x
ROD = (0.5, 0.32)  # rod xy; y chosen so only the arm's outer edge touches it
START_X = -0.025  # puts the single-substep touch at substep 1 of control step 5
CONTROL_STEPS = 12


@pytest.fixture(scope="module")
def model(robot_cfg) -> mujoco.MjModel:
    def add_rod(spec: mujoco.MjSpec) -> None:
        body = spec.worldbody.add_body(name=OBSTACLE_BODY, pos=[ROD[0], ROD[1], 0.0])
        body.add_geom(
            name="rod",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0, 0, 0.2, 0, 0, 1.8],
            size=[0.005, 0, 0],
            contype=0,
            conaffinity=OBSTACLE_BIT,
        )

    m = build_env_model(robot_cfg, add_rod)
    m.opt.gravity[:] = 0.0
    return m


def initial_state(cfg) -> tuple[torch.Tensor, torch.Tensor]:
    qpos = torch.as_tensor(home_qpos(cfg))[None].clone()
    qpos[0, 0], qpos[0, 2] = START_X, 1.0
    qvel = torch.zeros(1, 6 + cfg.num_joints, dtype=torch.float64)
    qvel[0, 0] = SPEED
    return qpos, qvel


def readings(backend, cfg, calls: int) -> np.ndarray:
    """Collision sensor after each of ``calls`` ``step`` calls from the initial state."""
    qpos, qvel = initial_state(cfg)
    backend.reset(torch.tensor([0]), qpos, qvel)
    col = backend.sensors[COLLISION_SENSOR].adr
    ctrl = torch.as_tensor(cfg.default_joint_pos, dtype=torch.float32)[None]
    out = []
    for _ in range(calls):
        backend.step(ctrl)
        out.append(float(backend.sensordata[0, col]))
    return np.array(out)


def substep_truth(sim: str, model, cfg) -> np.ndarray:
    """(CONTROL_STEPS, decimation) contact counts: the same simulator stepped one substep per call."""
    dec = cfg.decimation
    per_substep = readings(make_backend(sim, model, 1, 1), cfg, CONTROL_STEPS * dec).reshape(CONTROL_STEPS, dec)
    intermediate = (per_substep[:, :-1].max(axis=1) > 0) & (per_substep[:, -1] == 0)
    assert intermediate.any(), f"scenario has no intermediate-only contact: {per_substep.tolist()}"
    return per_substep


@pytest.mark.parametrize("sim", ["mujoco", "warp"])
def test_contact_at_an_intermediate_substep_is_flagged(model, robot_cfg, sim):
    if sim == "warp":
        pytest.importorskip("mujoco_warp")
    truth = substep_truth(sim, model, robot_cfg)
    flags = readings(make_backend(sim, model, 1, robot_cfg.decimation), robot_cfg, CONTROL_STEPS)
    np.testing.assert_array_equal(flags > 0, truth.max(axis=1) > 0)


def test_without_max_sensors_the_last_substep_misses_it(model, robot_cfg):
    """The old behaviour (last substep only) misses the touch, so the test above can fail."""
    truth = substep_truth("mujoco", model, robot_cfg)
    last_only = readings(MujocoBackend(model, 1, robot_cfg.decimation), robot_cfg, CONTROL_STEPS)
    assert truth.max() > 0 and last_only.max() == 0


def test_unknown_max_sensor_is_named(model):
    with pytest.raises(KeyError, match="max_sensors \\['nope'\\] not in the model"):
        MujocoBackend(model, 1, 4, max_sensors=("nope",))


def test_warp_buffer_overflow_raises_in_step(robot_cfg):
    pytest.importorskip("mujoco_warp")
    from cat.envs.sim.warp_backend import WarpBackend

    m = build_env_model(robot_cfg)
    tiny = WarpBackend(m, 2, robot_cfg.decimation, device="cpu", nconmax=2, njmax=8)
    with pytest.raises(RuntimeError, match=r"buffers overflowed in worlds .*raise WarpBackend nconmax"):
        for _ in range(15):  # zero targets: the robot folds up on the floor, > 2 contacts
            tiny.step(torch.zeros(2, m.nu))
