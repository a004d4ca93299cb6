"""``scripts/bench.py live``: the live perception path (LiDAR -> map -> window -> HumanoidPF) while the
simulation runs in real time beside it, as in the click demo.

Prints ``case=live grid=128x128x35 map_ms=<median> field_ms=<median> p95_ms=<p95 of the whole cycle> hz=<field
updates per wall-clock second>``. ``map_ms`` is scan (ray casting) + map update + window extraction.
"""

from __future__ import annotations

import argparse
import logging
import threading
import time

import numpy as np
import torch

from cat.deploy.policy import policy_spec
from cat.deploy.runtime import DeployCfg, Runtime
from cat.deploy.scenes import load_scene


def run(scene: str, seconds: float, warmup: float) -> dict:
    rt = Runtime(load_scene(scene), policy_spec("hold"), DeployCfg(realtime=True))
    rt.set_goal(tuple(rt.scene.goals[0, :2]))
    stop = threading.Event()
    robot = threading.Thread(target=rt.run, args=(stop,), daemon=True)
    robot.start()
    time.sleep(warmup)  # first cycles include kernel loading
    n0, t0 = rt.perception.field_updates, time.monotonic()
    time.sleep(seconds)
    n1, t1 = rt.perception.field_updates, time.monotonic()
    stop.set()
    robot.join(timeout=10)
    rt.stop()
    stats = [s for s in rt.perception.stats if s.wall >= t0 and s.field_ms > 0]
    if not stats:
        raise RuntimeError("no perception cycle finished in the measured window")
    shape = rt.deploy.perception.window.shape
    return {
        "grid": "x".join(str(v) for v in shape),
        "map_ms": float(np.median([s.map_ms for s in stats])),
        "field_ms": float(np.median([s.field_ms for s in stats])),
        "p95_ms": float(np.percentile([s.total_ms for s in stats], 95)),
        "hz": (n1 - n0) / (t1 - t0),
        "cycles": len(stats),
    }


def main(argv: list[str]) -> None:
    p = argparse.ArgumentParser(prog="bench.py live", description=__doc__)
    p.add_argument("--scene", default="hurdle-crouch", help="flat | typical type | scene folder | mesh file")
    p.add_argument("--seconds", type=float, default=20.0, help="measured wall-clock time")
    p.add_argument("--warmup", type=float, default=3.0)
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    torch.set_num_threads(1)
    r = run(args.scene, args.seconds, args.warmup)
    print(
        f"case=live grid={r['grid']} map_ms={r['map_ms']:.1f} field_ms={r['field_ms']:.1f} "
        f"p95_ms={r['p95_ms']:.1f} hz={r['hz']:.1f}"
    )
