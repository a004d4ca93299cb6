"""Run jobs through hydra's launcher plugins (``hydra/launcher=basic|joblib|submitit_local|submitit_slurm|ray``).

A job is a script's command line (``scripts/train.py`` overrides). Every job's overrides are validated by the
caller before any is launched; here hydra composes a minimal config whose ``hydra`` node holds the launcher,
instantiates the launcher plugin and hands it one override list per job. Each job then re-imports the script
file in its own process (joblib, submitit) or in this one (``basic``) and runs the same code path as the command
line, so what runs is exactly what ``python scripts/<name>.py <overrides>`` would run.
"""

from __future__ import annotations

import importlib.util
import inspect
import logging
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

from hydra.core.config_store import ConfigStore
from hydra.core.global_hydra import GlobalHydra

log = logging.getLogger(__name__)

LAUNCH_CONFIG = "cat_launch"
# hydra writes nothing into the job folders (the run folder must start empty) and changes no directory
QUIET = ["hydra.output_subdir=null", "hydra.job.chdir=false", "hydra/job_logging=none", "hydra/hydra_logging=none"]


class LauncherError(ValueError):
    """An unknown launcher or a bad ``hydra.*`` launcher override."""


def _ensure_logging() -> None:
    root = logging.getLogger()
    if not root.handlers:
        logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    root.setLevel(logging.INFO)


def load_script(path: str | Path):
    """``scripts/<name>.py`` as a module (its ``SCRIPT`` object), without running its ``__main__`` block."""
    path = Path(path)
    spec = importlib.util.spec_from_file_location(f"cat_script_{path.stem}", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses defined in the script look their module up
    spec.loader.exec_module(mod)
    return mod


@dataclass
class ScriptJob:
    """The task hydra's launcher runs: job ``k`` of ``jobs`` through the script at ``path`` (picklable)."""

    path: str
    jobs: list[list[str]]

    def __call__(self, cfg) -> JobResult:
        from hydra.core.hydra_config import HydraConfig

        _ensure_logging()
        k = int(HydraConfig.get().job.num)
        t0 = time.monotonic()
        code = run_script_job(self.path, self.jobs[k])
        return JobResult(int(code or 0), (time.monotonic() - t0) / 60.0)


class JobResult(NamedTuple):
    """A launched job's exit code and its own wall-clock minutes (None: it raised, the launcher did not time it)."""

    code: int
    minutes: float | None = None


def run_script_job(path: str | Path, overrides: list[str]) -> int:
    """Load and run one job of a script; a bad input is one ERROR line and code 2 (as on the command line)."""
    from cat.errors import CliError

    script = load_script(path).SCRIPT
    log.info("job: %s %s", Path(path).name, " ".join(overrides))
    try:
        return script.job(script.load(overrides))
    except (CliError, *script.errors) as err:
        log.error("%s", err)
        return 2


def script_path(job_fn) -> str:
    """The file of the script whose ``job`` function this is."""
    return str(Path(inspect.getfile(job_fn)).resolve())


def _hydra(name: str):
    from hydra._internal.hydra import Hydra
    from hydra._internal.utils import create_config_search_path

    ConfigStore.instance().store(name=LAUNCH_CONFIG, node={})
    GlobalHydra.instance().clear()
    return Hydra.create_main_hydra2(task_name=name, config_search_path=create_config_search_path(None))


def launcher_options() -> list[str]:
    """The launchers installed here (hydra's ``basic`` plus every launcher plugin's configs)."""
    try:
        hydra = _hydra("options")
        return sorted(hydra.config_loader.get_group_options("hydra/launcher"))
    finally:
        GlobalHydra.instance().clear()


def check_launcher(hydra_args: list[str]) -> None:
    """``LauncherError`` naming an unknown ``hydra/launcher=`` choice (with the installed ones) or a launcher key
    the chosen launcher does not have."""
    if not hydra_args:
        return
    for item in hydra_args:
        if item.split("=", 1)[0].lstrip("+") == "hydra/launcher":
            name = item.split("=", 1)[1]
            options = launcher_options()
            if name not in options:
                hint = " (ray: pip install hydra-ray-launcher)" if name.startswith("ray") else ""
                raise LauncherError(f"unknown hydra/launcher {name!r}{hint}; installed: {', '.join(options)}")
    try:
        _compose(_hydra("check"), hydra_args)
    finally:
        GlobalHydra.instance().clear()


def _compose(hydra, hydra_args: list[str]):
    from hydra.types import RunMode

    try:
        return hydra.config_loader.load_configuration(LAUNCH_CONFIG, [*QUIET, *hydra_args], RunMode.MULTIRUN)
    except Exception as err:  # hydra names the key; its cause says what is wrong with it
        reason = err.__cause__ or err.__context__
        detail = f": {str(reason).splitlines()[0]}" if reason is not None and str(reason) else ""
        raise LauncherError(f"bad launcher override: {str(err).splitlines()[0]}{detail}") from None


def launch(path: str | Path, jobs: list[list[str]], hydra_args: list[str], name: str | None = None) -> list[JobResult]:
    """Run ``jobs`` (override lists of the script at ``path``) through the launcher ``hydra_args`` select
    (``hydra/launcher=joblib``, ``hydra.launcher.n_jobs=2``, ``hydra.sweep.dir=...``); returns each job's exit
    code and minutes in order (code 1 for a job that raised)."""
    from hydra.core.hydra_config import HydraConfig
    from hydra.core.plugins import Plugins
    from hydra.core.utils import JobStatus
    from hydra.types import HydraContext

    check_launcher(hydra_args)
    name = name or Path(path).stem
    hydra = _hydra(name)
    try:
        cfg = _compose(hydra, hydra_args)
        HydraConfig.instance().set_config(cfg)
        from hydra._internal.callbacks import Callbacks

        launcher = Plugins.instance().instantiate_launcher(
            hydra_context=HydraContext(config_loader=hydra.config_loader, callbacks=Callbacks(cfg)),
            task_function=ScriptJob(str(Path(path).resolve()), [list(j) for j in jobs]),
            config=cfg,
        )
        log.info("launching %d job(s) of %s with hydra/launcher=%s", len(jobs), name, cfg.hydra.launcher._target_)
        # the overrides are shown by the launcher and name each job; the job reads its own from ``jobs``
        shown = [[_shown(o) for o in job] for job in jobs]
        returns = launcher.launch(shown, initial_job_idx=0)
    finally:
        GlobalHydra.instance().clear()
    results = []
    for k, ret in enumerate(returns):
        if ret.status == JobStatus.COMPLETED:
            results.append(JobResult(*ret.return_value))
        else:
            log.error("job %d (%s) failed: %s", k, " ".join(jobs[k]), ret._return_value)
            results.append(JobResult(1))
    return results


def _shown(override: str) -> str:
    """An override as hydra may compose it onto the empty launch config (force-add the key)."""
    return override if override.startswith(("~", "++")) else "++" + override.lstrip("+")
