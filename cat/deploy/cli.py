"""``scripts/click_and_traverse.py`` on the shared command line (``cat.cli``): set-up and the two modes.

Bad input (missing scene or mesh, unreadable checkpoint, a goal inside an obstacle, ...) ends with one ERROR
line on stderr and exit code 2, no traceback.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

import torch

from cat.checkpoint_io import CheckpointError
from cat.cli import CliError, Script, dataclass_loader, run
from cat.deploy.perception import PerceptionCfg
from cat.deploy.policy import policy_spec
from cat.deploy.runtime import DeployCfg, Runtime
from cat.deploy.scenes import GoalError, load_scene
from cat.envs.robot import MenagerieModelError
from cat.terrain import SceneError

log = logging.getLogger("click_and_traverse")

DOC = """Click-and-Traverse (paper §III-C) in simulation with live perception (docs/demo.md).

  python scripts/click_and_traverse.py scene=<flat|typical type|scene folder|mesh> checkpoint=<model.pt|x.onnx|hold>
      starts the browser view on http://host:port (printed); click the floor to send the G1 there.
  ... goal=x,y [time_limit=20] [record=run.rrd]
      headless: prints success=<0|1> time_s=<t> distance_error=<m> collisions=<n> field_updates_hz=<f>
"""


@dataclass
class ClickCfg:
    scene: str = "???"  # flat | typical type (hurdle-crouch, ...) | scene folder | mesh file (OBJ/PLY/STL)
    checkpoint: str = "???"  # rsl_rl model_*.pt (config.yaml beside it) | run folder | exported .onnx | hold
    goal: str = ""  # "x,y": headless, no browser
    time_limit: float = 20.0  # headless: seconds of robot time after the goal is set (the trial window)
    record: str = ""  # headless: .rrd path for rerun
    host: str = "127.0.0.1"
    port: int = 8080
    start: str = ""  # "x,y" start for mesh scenes (default: the scene's start, the origin for meshes)
    realtime: bool = True  # False: lockstep perception (reproducible, as fast as the CPU allows)
    seed: int = 0
    torch_threads: int = 1  # the control loop is tiny; more threads only contend with perception


def parse_xy(text: str, name: str) -> tuple[float, float]:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise CliError(f"{name} must be x,y (two numbers), got {text!r}") from None
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


def job(cfg: ClickCfg) -> int:
    logging.getLogger("websockets").setLevel(logging.WARNING)
    torch.set_num_threads(max(1, cfg.torch_threads))
    goal = parse_xy(cfg.goal, "goal") if cfg.goal else None
    if cfg.time_limit <= 0:
        raise CliError(f"time_limit must be > 0, got {cfg.time_limit}")
    rt = build_runtime(cfg)
    if goal is None:
        if cfg.record:
            log.warning("record= is for headless runs (goal=x,y); ignored")
        run_browser(rt, cfg)
        return 0
    from cat.deploy.headless import run_headless
    from cat.deploy.record import LiveRecorder

    recorder = LiveRecorder(cfg.record, rt) if cfg.record else None
    print(run_headless(rt, goal, cfg.time_limit, recorder).line(), flush=True)
    return 0


SCRIPT = Script(
    name="click_and_traverse",
    doc=DOC,
    load=dataclass_loader(ClickCfg, required=("scene", "checkpoint")),
    job=job,
    keys=list(ClickCfg.__dataclass_fields__),
    errors=(SceneError, CheckpointError, GoalError, MenagerieModelError, OSError, ValueError),
)


def main(argv: list[str]) -> int:
    return run(SCRIPT, argv)
