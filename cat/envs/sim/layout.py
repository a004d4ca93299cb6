"""What lets MuJoCo models share one simulation: ``MjData`` layouts and the robot's state, control and sensor sizes.

Physics-layer checks on compiled models, read by the backends (a model table, the warp slot models) and by the
per-world scene models that build them (``cat.envs.scene_models``); they import nothing from the env.
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco

from cat.envs.sim.base import state_layout

PAD_BODY = "obstacle_pad"
"""The body holding a padded scene model's spare geoms (``cat.envs.scene_models``, the warp slot models)."""

_LAYOUT_SIZES = (
    "nq", "nv", "nu", "na", "nbody", "njnt", "ngeom", "nsite", "ncam", "nlight", "nbvh", "nbvhdynamic", "nmocap",
    "neq", "ntendon", "nwrap", "nsensordata", "nuserdata", "nplugin", "npluginstate", "ntree", "nflex",
    "nflexvert", "nflexedge", "nflexelem", "nflexstiffness", "nJmom", "nJten", "nJfe", "nM", "nD", "nB", "nC",
    "nhistory", "nplastic", "nout", "narena",
)  # fmt: skip
"""Model sizes that MjData's arrays are allocated from (mjxmacro.h ``MJDATA_POINTERS``), plus the arena."""

_ROBOT_SIZES = ("nq", "nv", "nu", "na", "nsensordata")


class SceneModelError(ValueError):
    """Scene models that cannot share one simulation (state or sensor sizes differ)."""


def data_layout(model: mujoco.MjModel) -> tuple[int, ...]:
    """The sizes ``MjData(model)``'s layout depends on: models with equal layouts can share one ``MjData``."""
    return tuple(int(getattr(model, n)) for n in _LAYOUT_SIZES if hasattr(model, n))


def check_same_layout(models: Sequence[mujoco.MjModel]) -> None:
    """Have MuJoCo confirm that ``models`` give ``MjData`` one layout (``mujoco.batch``, MuJoCo >= 4.0, checks
    every size it allocates from; ``data_layout`` is our reading of them). Raises :class:`SceneModelError`."""
    try:
        from mujoco import batch
    except ImportError:  # older MuJoCo: data_layout alone
        return
    try:
        batch.Batch(models[0], nsim=len(models), nthread=1).set_models(list(models))
    except Exception as err:  # mujoco raises a plain error naming the model index
        raise SceneModelError(f"models of one data_layout do not share MjData's layout: {err}") from err


def robot_sizes(model: mujoco.MjModel) -> dict[str, int]:
    """Sizes of what the env reads and writes (state vector, controls, sensors): equal in every scene model."""
    out = {n: int(getattr(model, n)) for n in _ROBOT_SIZES}
    out["nstate"] = state_layout(model)[0]
    return out


def check_compatible(models: Sequence[mujoco.MjModel], names: Sequence[str] | None = None) -> None:
    """Raise :class:`SceneModelError` naming the first model whose state, control or sensor sizes differ."""
    ref = robot_sizes(models[0])
    for i, m in enumerate(models[1:], start=1):
        got = robot_sizes(m)
        if got != ref:
            diff = ", ".join(f"{k} {got[k]} != {ref[k]}" for k in ref if got[k] != ref[k])
            name = names[i] if names is not None else f"model {i}"
            first = names[0] if names is not None else "model 0"
            raise SceneModelError(
                f"{name}: {diff} (of {first}); obstacles must be static (no joints, actuators, sensors)"
            )
