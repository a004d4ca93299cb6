"""``scripts/click_and_traverse.py``: arguments, set-up and the two modes (browser, headless).

Bad input (missing scene or mesh, unreadable checkpoint, a goal inside an obstacle, ...) ends with one line
on stderr and exit code 2, no traceback.
"""

from __future__ import annotations

import logging
import sys
import threading
from dataclasses import dataclass, fields

import torch
from omegaconf import OmegaConf

from cat.deploy.perception import PerceptionCfg
from cat.deploy.policy import policy_spec
from cat.deploy.runtime import DeployCfg, Runtime
from cat.deploy.scenes import GoalError, load_scene
from cat.envs.robot import MenagerieModelError
from cat.learning.runs import CheckpointError
from cat.terrain import SceneError

log = logging.getLogger("click_and_traverse")


@dataclass
class ClickCfg:
    scene: str = "???"  # flat | typical type (hurdle-crouch, ...) | scene folder | mesh file (OBJ/PLY/STL)
    checkpoint: str = "???"  # rsl_rl model_*.pt (config.yaml beside it) | hold (zero actions)
    goal: str = ""  # "x,y": headless, no browser
    time_limit: float = 20.0  # headless: seconds of robot time after the goal is set
    record: str = ""  # headless: .rrd path for rerun
    host: str = "127.0.0.1"
    port: int = 8080
    start: str = ""  # "x,y" start for mesh scenes (default: the scene's start, the origin for meshes)
    realtime: bool = True  # False: lockstep perception (reproducible, as fast as the CPU allows)
    seed: int = 0
    torch_threads: int = 1  # the control loop is tiny; more threads only contend with perception


class UsageError(ValueError):
    """Bad command-line arguments."""


def parse_args(argv: list[str]) -> ClickCfg:
    try:
        merged = OmegaConf.merge(OmegaConf.structured(ClickCfg), OmegaConf.from_dotlist(argv))
    except Exception as err:
        valid = ", ".join(f.name for f in fields(ClickCfg))
        reason = str(err).splitlines()[0]
        raise UsageError(f"bad arguments {argv}: {reason} (valid keys: {valid})") from None
    for key in ("scene", "checkpoint"):
        if OmegaConf.is_missing(merged, key):
            raise UsageError(f"missing {key}=<...> (usage: scene=<type|folder|mesh> checkpoint=<model_*.pt|hold>)")
    return OmegaConf.to_object(merged)


def parse_xy(text: str, name: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"{name} must be x,y (two numbers), got {text!r}") from None
    return x, y


def build_runtime(cfg: ClickCfg) -> Runtime:
    """Scene + policy + runtime; raises SceneError / CheckpointError / ValueError on bad input."""
    start = parse_xy(cfg.start, "start") if cfg.start else None
    scene = load_scene(cfg.scene, start_xy=start, seed=cfg.seed)
    spec = policy_spec(cfg.checkpoint)
    deploy = DeployCfg(perception=PerceptionCfg(), realtime=cfg.realtime, seed=cfg.seed)
    return Runtime(scene, spec, deploy)


def run_browser(rt: Runtime, cfg: ClickCfg) -> None:
    from cat.deploy.viewer import ClickApp, ViewerCfg

    app = ClickApp(rt, ViewerCfg(host=cfg.host, port=cfg.port))
    app.start()
    print(app.url, flush=True)
    try:
        threading.Event().wait()
    except KeyboardInterrupt:
        pass
    finally:
        app.stop()


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    logging.getLogger("websockets").setLevel(logging.WARNING)
    try:
        cfg = parse_args(argv)
        torch.set_num_threads(max(1, cfg.torch_threads))
        goal = parse_xy(cfg.goal, "goal") if cfg.goal else None
        rt = build_runtime(cfg)
        if goal is None:
            if cfg.record:
                log.warning("record= is for headless runs (goal=x,y); ignored")
            run_browser(rt, cfg)
            return 0
        from cat.deploy.headless import run_headless
        from cat.deploy.record import LiveRecorder

        recorder = LiveRecorder(cfg.record, rt) if cfg.record else None
        result = run_headless(rt, goal, cfg.time_limit, recorder)
    except (UsageError, SceneError, CheckpointError, GoalError, MenagerieModelError, OSError) as err:
        log.error("%s", err)
        return 2
    except ValueError as err:  # e.g. a policy whose observation a robot cannot compute
        log.error("%s", err)
        return 2
    print(result.line(), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
