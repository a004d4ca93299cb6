"""G1 robot description (robots/g1/g1.yaml) and the MuJoCo scene composed from it with ``mujoco.MjSpec``.

Collision convention, shared with ``cat.terrain`` (obstacles) and the physics backends:

* robot collision geoms: ``contype = OBSTACLE_BIT | FLOOR_BIT`` (foot boxes: ``OBSTACLE_BIT`` only),
  ``conaffinity = 0`` -> no robot self-collision;
* floor: ``contype = 0``, ``conaffinity = FLOOR_BIT``;
* obstacles: ``contype = 0``, ``conaffinity = OBSTACLE_BIT``, all attached to one static body named
  ``OBSTACLE_BODY`` so a single contact sensor reports any robot-obstacle touch.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np
import yaml

from cat.envs.sim.base import write_pd_gains
from cat.errors import SetupError
from cat.terrain.mujoco_export import OBSTACLE_BIT, OBSTACLE_BODY  # noqa: F401  (the one definition, re-exported)

FLOOR_BIT = 2
QUERY_SITE_PREFIX = "query_"
ROBOT_CFG_PATH = Path(__file__).resolve().parents[2] / "robots" / "g1" / "g1.yaml"


class MenagerieModelError(SetupError):
    """The menagerie robot model could not be found or downloaded."""


@dataclass
class QueryLink:
    name: str
    body: str
    offset: tuple[float, float, float]


@dataclass
class RobotCfg:
    """Everything the library needs to know about the robot, read from ``robots/g1/g1.yaml``."""

    model_name: str
    model_entry: str
    timestep: float
    decimation: int
    base_height: float
    root_body: str
    action_scale: float
    soft_limit_factor: float
    joint_names: list[str]
    default_joint_pos: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    torque_limit: np.ndarray
    policy_joints: list[str]
    query_links: list[QueryLink]
    feet: list[str]
    collision_geoms: list[str]
    floor_geoms_exclude: list[str] = field(default_factory=list)
    foot_sole: tuple[float, float] | None = None  # heel and toe along the foot's x axis from its query point [m]

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def policy_joint_ids(self) -> list[int]:
        return [self.joint_names.index(j) for j in self.policy_joints]

    @property
    def query_site_names(self) -> list[str]:
        return [QUERY_SITE_PREFIX + q.name for q in self.query_links]

    @property
    def control_dt(self) -> float:
        return self.timestep * self.decimation


def load_robot_cfg(path: str | os.PathLike | None = None) -> RobotCfg:
    """Read the robot description yaml (default: ``robots/g1/g1.yaml``)."""
    path = Path(path) if path is not None else ROBOT_CFG_PATH
    if not path.is_file():
        raise FileNotFoundError(f"robot description not found: {path}")
    raw = yaml.safe_load(path.read_text())
    joints = raw["joints"]
    links = [QueryLink(n, b, tuple(float(v) for v in o)) for n, b, o in raw["query_links"]]
    if len(links) != 13:
        raise ValueError(f"{path}: HumanoidPF needs 13 query links, found {len(links)}")
    names = [j[0] for j in joints]
    for pj in raw["policy_joints"]:
        if pj not in names:
            raise ValueError(f"{path}: policy joint {pj!r} is not among the actuated joints")
    return RobotCfg(
        model_name=raw["model"]["name"],
        model_entry=raw["model"]["entry"],
        timestep=float(raw["timestep"]),
        decimation=int(raw["decimation"]),
        base_height=float(raw["base_height"]),
        root_body=raw["root_body"],
        action_scale=float(raw["action_scale"]),
        soft_limit_factor=float(raw["soft_limit_factor"]),
        joint_names=names,
        default_joint_pos=np.array([j[1] for j in joints], dtype=np.float64),
        kp=np.array([j[2] for j in joints], dtype=np.float64),
        kd=np.array([j[3] for j in joints], dtype=np.float64),
        torque_limit=np.array([j[4] for j in joints], dtype=np.float64),
        policy_joints=list(raw["policy_joints"]),
        query_links=links,
        feet=list(raw["feet"]),
        collision_geoms=list(raw["collision_geoms"]),
        floor_geoms_exclude=list(raw.get("floor_geoms_exclude", [])),
        foot_sole=_foot_sole(raw.get("foot_sole"), path),
    )


def _foot_sole(raw, path: Path) -> tuple[float, float] | None:
    if raw is None:
        return None
    if len(raw) != 2 or not float(raw[0]) < float(raw[1]):
        raise ValueError(f"{path}: foot_sole must be [heel, toe] offsets with heel < toe, got {raw}")
    return float(raw[0]), float(raw[1])


def menagerie_model_path(cfg: RobotCfg) -> Path:
    """Path of the robot's MJCF file, from ``MENAGERIE_ROOT`` (offline) or the package's download cache."""
    import mujoco_menagerie

    try:
        robot = mujoco_menagerie.get(cfg.model_name)
        entry = next(e for e in robot.entry_points if e.name == cfg.model_entry)
        path = Path(robot.path()) / entry.file
    except StopIteration:
        raise MenagerieModelError(f"menagerie robot {cfg.model_name!r} has no entry {cfg.model_entry!r}") from None
    except Exception as err:  # download or registry failure
        raise MenagerieModelError(
            f"could not load menagerie model {cfg.model_name!r} ({err}). Set MENAGERIE_ROOT to a local "
            "mujoco_menagerie checkout (e.g. MENAGERIE_ROOT=../shared/menagerie) or go online so the "
            "mujoco-menagerie package can download it."
        ) from err
    if not path.is_file():
        raise MenagerieModelError(
            f"menagerie model file missing: {path}. Set MENAGERIE_ROOT to a folder holding {cfg.model_name}/"
        )
    return path


def robot_spec(cfg: RobotCfg | None = None, floor: bool = True) -> mujoco.MjSpec:
    """The G1 as an ``MjSpec``: gains/limits from ``cfg``, 13 query sites, collision bits, optional floor.

    Obstacles are added later by ``cat.terrain`` (see the module docstring for the collision bits).
    """
    cfg = cfg or load_robot_cfg()
    spec = mujoco.MjSpec.from_file(str(menagerie_model_path(cfg)))
    spec.option.timestep = cfg.timestep
    _configure_actuators(spec, cfg)
    _configure_collisions(spec, cfg)
    for q in cfg.query_links:
        body = spec.body(q.body)
        if body is None:
            raise ValueError(f"query link {q.name!r}: body {q.body!r} not in the model")
        body.add_site(name=QUERY_SITE_PREFIX + q.name, pos=list(q.offset), size=[0.015, 0, 0], group=5)
    if floor:
        spec.worldbody.add_geom(
            name="floor",
            type=mujoco.mjtGeom.mjGEOM_PLANE,
            size=[0, 0, 0.01],
            contype=0,
            conaffinity=FLOOR_BIT,
            condim=3,
            friction=[1.0, 0.005, 0.0001],
            rgba=[0.25, 0.3, 0.35, 1],
        )
    spec.add_key(name="home", qpos=home_qpos(cfg).tolist(), ctrl=cfg.default_joint_pos.tolist())
    return spec


def home_qpos(cfg: RobotCfg) -> np.ndarray:
    """Standing pose: base at ``base_height``, identity orientation, joints at their defaults."""
    return np.concatenate([[0.0, 0.0, cfg.base_height, 1.0, 0.0, 0.0, 0.0], cfg.default_joint_pos])


def _configure_actuators(spec: mujoco.MjSpec, cfg: RobotCfg) -> None:
    names = [a.name for a in spec.actuators]
    if names != cfg.joint_names:
        raise ValueError(f"robot yaml joint order differs from the model's actuators: {names}")
    for act, kp, kd, tau in zip(spec.actuators, cfg.kp, cfg.kd, cfg.torque_limit, strict=True):
        # Position servo: force = kp (ctrl - q) - kd qdot, clamped to the torque limit.
        write_pd_gains(act.gainprm, act.biasprm, kp, kd)
        act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.forcerange = [-tau, tau]


def _configure_collisions(spec: mujoco.MjSpec, cfg: RobotCfg) -> None:
    spec.pairs.clear() if hasattr(spec.pairs, "clear") else None
    wanted = set(cfg.collision_geoms)
    found = set()
    for geom in spec.geoms:
        if geom.name in wanted:
            found.add(geom.name)
            floor = 0 if geom.name in cfg.floor_geoms_exclude else FLOOR_BIT
            geom.contype = OBSTACLE_BIT | floor
            geom.conaffinity = 0
            geom.condim = 3
        else:
            geom.contype = 0
            geom.conaffinity = 0
    missing = wanted - found
    if missing:
        raise ValueError(f"collision geoms not in the model: {sorted(missing)}")


def compile_model(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """Compile a spec, turning MuJoCo's compiler error into one that names the problem."""
    try:
        return spec.compile()
    except ValueError as err:
        raise ValueError(f"MuJoCo could not compile the scene: {err}") from err
