"""Scenes (paper §III-B): typical types, procedural obstacles, indoor crops, mesh I/O, MuJoCo export.

Knows nothing of ``cat.envs``: the MuJoCo export takes an ``MjSpec`` and shares only the collision
constants ``OBSTACLE_BODY``/``OBSTACLE_BIT``, defined in ``mujoco_export`` (the env and the physics layer import
them from there).
"""

from cat.terrain.front3d import Front3DError, load_front3d
from cat.terrain.furniture import House, make_house
from cat.terrain.graded import NOT_GRADED, Graded
from cat.terrain.indoor import IndoorCfg, make_indoor
from cat.terrain.procedural import ProceduralCfg, make_procedural
from cat.terrain.scene import GOAL_HEIGHT, Scene, SceneError, check_scene, load_mesh
from cat.terrain.typical import (
    TYPICAL_KINDS,
    kind_name,
    make_typical,
    typical_variants,
    warmup_variants,
)
from cat.terrain.voxel import VOXEL, GridSpec, ReachCfg

__all__ = [
    "GOAL_HEIGHT",
    "TYPICAL_KINDS",
    "kind_name",
    "VOXEL",
    "Front3DError",
    "GridSpec",
    "House",
    "IndoorCfg",
    "ProceduralCfg",
    "ReachCfg",
    "Scene",
    "SceneError",
    "check_scene",
    "load_front3d",
    "load_mesh",
    "make_house",
    "make_indoor",
    "make_procedural",
    "Graded",
    "NOT_GRADED",
    "make_typical",
    "typical_variants",
    "warmup_variants",
]
