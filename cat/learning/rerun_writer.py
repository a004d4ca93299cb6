"""rsl_rl ``LogWriter`` that records training scalars to a rerun ``.rrd`` file in the run folder."""

from __future__ import annotations

import json
import os

import rerun as rr
from rsl_rl.utils.log_writer import LogWriter


class RerunLogWriter(LogWriter):
    """Scalars go to ``<log_dir>/metrics.rrd`` on an ``iteration`` timeline (open with ``rerun metrics.rrd``).

    The same scalars are appended to ``metrics.csv`` (iteration, tag, value) for plotting without a viewer
    (``scripts/plot_training.py``). A resumed run appends to the csv and records to the next free
    ``metrics_<k>.rrd`` (open them together: ``rerun <run>/metrics*.rrd``).
    """

    def __init__(self, log_dir: str, recording_name: str = "cat_training", **_unused):
        os.makedirs(log_dir, exist_ok=True)
        self.path = os.path.join(log_dir, "metrics.rrd")
        k = 0
        while os.path.exists(self.path):
            k += 1
            self.path = os.path.join(log_dir, f"metrics_{k}.rrd")
        self.rec = rr.RecordingStream(recording_name)
        self.rec.save(self.path)
        self._csv = open(os.path.join(log_dir, "metrics.csv"), "a", buffering=1)  # noqa: SIM115
        if self._csv.tell() == 0:
            self._csv.write("iteration,tag,value\n")

    def add_scalar(self, tag: str, scalar_value: float, global_step: int) -> None:
        if tag.endswith("/time"):  # rsl_rl's copies indexed by elapsed seconds: their own timeline, not the csv
            self.rec.reset_time()
            self.rec.set_time("elapsed_s", sequence=int(global_step))
            self.rec.log(tag, rr.Scalars(float(scalar_value)))
            return
        self.rec.reset_time()
        self.rec.set_time("iteration", sequence=int(global_step))
        self.rec.log(tag, rr.Scalars(float(scalar_value)))
        self._csv.write(f"{int(global_step)},{tag},{float(scalar_value):.6g}\n")

    def store_config(self, env_cfg, train_cfg: dict) -> None:
        self.rec.log("config", rr.TextDocument(json.dumps(train_cfg, indent=2, default=str)), static=True)

    def stop(self) -> None:
        self.rec.flush()
        self._csv.close()


def prune_metrics(csv_path: str | os.PathLike, first_iteration: int) -> int:
    """Drop ``metrics.csv`` rows of iterations >= ``first_iteration``: what a run logged after the checkpoint it
    is resumed from (a kill or crash past the last save) is redone, so the curve has one value per iteration.
    Rewritten through a temporary file; returns how many rows went."""
    if not os.path.isfile(csv_path):
        return 0
    with open(csv_path) as f:
        lines = f.readlines()
    keep = [ln for ln in lines[1:] if int(ln.split(",", 1)[0]) < first_iteration]
    dropped = len(lines) - 1 - len(keep)
    if dropped:
        tmp = f"{csv_path}.tmp"
        with open(tmp, "w") as f:
            f.writelines(lines[:1] + keep)
        os.replace(tmp, csv_path)
    return dropped
