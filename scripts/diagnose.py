"""Play a checkpoint under a condition the method does not ship, to test a hypothesis (docs/results.md, issue 28).

``python scripts/diagnose.py <case> [case keys] <play.py keys>``, cases:

- ``arms roll=<rad>``: the default shoulder roll of both arms set to +/-``roll`` (robots/g1/g1.yaml: 0.3) for the
  play only; the policy is untouched (its joint observations are relative to the default pose, so it sees the
  arm where it always was while the body is narrower or wider).
- ``symmetrised``: each action is the mean of the policy's and its mirror image's (mirrored observation in,
  mirrored action out; ``cat.envs.symmetry.MirrorMap``): whether a lateralised policy averages into a two-sided one.

Everything after the case goes to ``scripts/play.py`` (``checkpoint=``, ``scene_dir=``, ``contacts=true``, ...),
which prints its usual lines.
"""

from __future__ import annotations

import logging
import re
import sys
import tempfile
from pathlib import Path

import torch

import cat.envs.robot as robot
import cat.learning.play as play
from cat.envs.symmetry import MirrorMap
from cat.launcher import load_script

log = logging.getLogger("cat.diagnose")
CASES = ("arms", "symmetrised")


def _arms(roll: float) -> Path:
    """A copy of the robot description with the shoulder roll defaults at +/-``roll``; the loader reads it."""
    text = robot.ROBOT_CFG_PATH.read_text()
    out, n = re.subn(r"(left_shoulder_roll_joint,\s+)(-?[\d.]+)", rf"\g<1>{roll}", text)
    out, m = re.subn(r"(right_shoulder_roll_joint,\s+)(-?[\d.]+)", rf"\g<1>{-roll}", out)
    if n != 1 or m != 1:
        raise ValueError(f"{robot.ROBOT_CFG_PATH}: no single shoulder roll default to change")
    path = Path(tempfile.mkdtemp(prefix="cat_arms_")) / "g1.yaml"
    path.write_text(out)
    return path


class _Symmetrised(torch.nn.Module):
    def __init__(self, policy, mirror: MirrorMap):
        super().__init__()
        self.policy, self.mirror = policy, mirror

    def forward(self, obs):
        mirrored = self.mirror.mirror_actions(self.policy(self.mirror.mirror_obs(obs)))
        return 0.5 * (self.policy(obs) + mirrored)

    def reset(self, *args, **kwargs):
        if hasattr(self.policy, "reset"):
            self.policy.reset(*args, **kwargs)


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    if not argv or argv[0] not in CASES:
        log.error("first argument: a case, one of %s (got %s)", ", ".join(CASES), argv[0] if argv else "nothing")
        return 2
    case, rest = argv[0], argv[1:]
    if case == "arms":
        given = [a for a in rest if a.startswith("roll=")]
        try:
            roll = float(given[-1].split("=", 1)[1])
        except (IndexError, ValueError):
            log.error("arms needs roll=<radians>, e.g. roll=0.1 (the robot's default is 0.3)")
            return 2
        rest = [a for a in rest if not a.startswith("roll=")]
        robot.ROBOT_CFG_PATH = _arms(roll)
        log.info("shoulder roll defaults +/-%g rad (%s)", roll, robot.ROBOT_CFG_PATH)
    else:
        load = play.load_policy

        def symmetrised(checkpoint, env, cfg):
            return _Symmetrised(load(checkpoint, env, cfg), MirrorMap.of_env(env)).eval()

        play.load_policy = symmetrised
    return load_script(Path(__file__).with_name("play.py")).main(rest)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
