"""Command-line front end shared by the scripts: hydra-style overrides with what hydra users type.

``key=value`` overrides, ``--help`` / ``-h``, ``--cfg job`` (print the resolved config, build nothing), ``-m`` /
``--multirun`` (one job per combination of comma-separated values, in sequence in this process, or through
hydra's launcher plugins with ``hydra/launcher=joblib|submitit_local|submitit_slurm|...`` and
``hydra.launcher.<key>=`` settings: ``cat/launcher.py``), ``hydra.run.dir=<dir>`` and ``hydra.sweep.dir=<dir>``
(mapped to a script's own output key). Every job is validated before the first runs. Any failure is one line on
stderr and exit code 2: unknown keys answer with the closest valid names.
"""

from __future__ import annotations

import difflib
import itertools
import logging
from collections.abc import Callable
from dataclasses import dataclass, field, fields, is_dataclass
from typing import Any

from omegaconf import OmegaConf

from cat.errors import CliError, SetupError

log = logging.getLogger("cat")


@dataclass
class Script:
    """How one script plugs into ``run``."""

    name: str
    doc: str  # usage text for --help
    load: Callable[[list[str]], Any]  # overrides -> validated config object (raises on bad input)
    job: Callable[[Any], int]  # config -> exit code
    run_dir_key: str | None = None  # config key that hydra.run.dir / hydra.sweep.dir map to (an output folder)
    groups: dict[str, list[str]] = field(default_factory=dict)  # config group -> options, for --help
    keys: list[str] = field(default_factory=list)  # common keys, for --help
    errors: tuple[type[BaseException], ...] = ()  # exception types reported as one line
    # job(config, launcher overrides): the script launches jobs itself (scripts/experiment.py), so hydra/launcher=
    # and hydra.launcher.<key>= reach it without -m
    uses_launcher: bool = False


def valid_keys(schema, prefix: str = "") -> list[str]:
    """Dotted keys of a dataclass schema (nested dataclasses expanded)."""
    keys = []
    for f in fields(schema):
        default = f.default_factory() if callable(f.default_factory) else f.default  # type: ignore[misc]
        if is_dataclass(default):
            keys += valid_keys(default, prefix + f.name + ".")
        else:
            keys.append(prefix + f.name)
    return keys


def unknown_key_message(key: str, valid: list[str]) -> str:
    close = difflib.get_close_matches(key, valid, n=3, cutoff=0.6)
    leaf = [k for k in valid if k.split(".")[-1] == key.split(".")[-1]]
    hints = list(dict.fromkeys(close + leaf))[:3]
    hint = f"; did you mean {' or '.join(hints)}?" if hints else "; see --help"
    return f"unknown key {key!r}{hint}"


def expand_sweep(overrides: list[str]) -> list[list[str]]:
    """Every combination of comma-separated sweep values (hydra's basic sweeper order)."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    try:
        parsed = OverridesParser.create().parse_overrides(overrides)
    except Exception as err:
        raise CliError(f"bad override: {err}") from None
    axes = []
    for item, ov in zip(overrides, parsed, strict=True):
        key = item.split("=", 1)[0]
        values = list(ov.sweep_string_iterator()) if ov.is_sweep_override() else [item.split("=", 1)[1]]
        axes.append([f"{key}={v}" for v in values])
    return [list(combo) for combo in itertools.product(*axes)]


def _split(argv: list[str]) -> tuple[dict[str, Any], list[str]]:
    flags: dict[str, Any] = {
        "help": False,
        "cfg": None,
        "multirun": False,
        "run_dir": None,
        "sweep_dir": None,
        "launcher": [],  # hydra/launcher=<name>, hydra.launcher.<key>=<value>
    }
    overrides, i = [], 0
    while i < len(argv):
        a = argv[i]
        if a in ("-h", "--help"):
            flags["help"] = True
        elif a in ("-m", "--multirun"):
            flags["multirun"] = True
        elif a in ("-c", "--cfg"):
            if i + 1 >= len(argv) or argv[i + 1] not in ("job", "all"):
                raise CliError("--cfg takes 'job' (print the resolved config)")
            flags["cfg"], i = argv[i + 1], i + 1
        elif a.startswith("hydra.run.dir="):
            flags["run_dir"] = a.split("=", 1)[1]
        elif a.startswith("hydra.sweep.dir="):
            flags["sweep_dir"] = a.split("=", 1)[1]
        elif a.lstrip("+").startswith(("hydra/launcher=", "hydra.launcher.")):
            flags["launcher"].append(a)
        elif a.startswith(("hydra.", "hydra/")):
            raise CliError(
                f"{a.split('=', 1)[0]!r} is not supported here "
                "(hydra.run.dir, hydra.sweep.dir, hydra/launcher=, hydra.launcher.<key>= are)"
            )
        elif a.startswith("-"):
            raise CliError(f"unknown option {a!r}; options: --help, --cfg job, -m/--multirun")
        elif "=" not in a:
            raise CliError(f"override {a!r} is not key=value")
        else:
            overrides.append(a)
        i += 1
    return flags, overrides


def _help(script: Script) -> str:
    lines = [script.doc.strip(), ""]
    for group, options in script.groups.items():
        lines.append(f"  {group}={{{','.join(options)}}}")
    if script.keys:
        lines.append("  common keys: " + ", ".join(script.keys))
    lines.append("  flags: --help, --cfg job (print the resolved config), -m/--multirun (sweep a=x,y),")
    lines.append("         hydra.run.dir=<dir>, hydra.sweep.dir=<dir> (with -m: one subfolder per job),")
    lines.append("         hydra/launcher=joblib|submitit_local|submitit_slurm (with -m: jobs in parallel processes")
    lines.append("         or on a cluster; hydra.launcher.<key>=<value> sets its options: docs/experiments.md)")
    return "\n".join(lines)


def run(script: Script, argv: list[str]) -> int:
    """Parse ``argv`` and run ``script``'s job(s); returns the exit code."""
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    from cat.launcher import LauncherError

    err_types = (CliError, SetupError, LauncherError, *script.errors)
    try:
        flags, overrides = _split(argv)
        if flags["help"]:
            print(_help(script))
            return 0
        jobs = expand_sweep(overrides) if flags["multirun"] else [overrides]
        if len(jobs) > 1 and not flags["multirun"]:
            raise CliError("comma-separated values need -m (multirun)")
        configs = []
        for k, job in enumerate(jobs):
            out_dir = flags["run_dir"] if not flags["multirun"] else None
            if flags["multirun"] and flags["sweep_dir"]:
                out_dir = f"{flags['sweep_dir']}/{k}"
            if out_dir is not None:
                if script.run_dir_key is None:
                    raise CliError(f"{script.name} writes no output folder: drop hydra.run.dir / hydra.sweep.dir")
                job = [*job, f"{script.run_dir_key}={out_dir}"]
            configs.append(script.load(job))  # validate every job before running any
        if flags["launcher"]:
            from cat.launcher import check_launcher

            check_launcher(flags["launcher"])
        if flags["cfg"]:
            for cfg in configs:
                print(OmegaConf.to_yaml(OmegaConf.structured(cfg)))
            return 0
        if flags["multirun"] and flags["launcher"]:
            from cat.launcher import launch, script_path

            hydra_args = list(flags["launcher"])
            if flags["sweep_dir"]:
                hydra_args.append(f"hydra.sweep.dir={flags['sweep_dir']}")
            full = [[*job, f"{script.run_dir_key}={flags['sweep_dir']}/{k}"] for k, job in enumerate(jobs)]
            results = launch(script_path(script.job), full if flags["sweep_dir"] else jobs, hydra_args, script.name)
            return max(r.code for r in results)
        if script.uses_launcher:
            return max(script.job(cfg, flags["launcher"]) for cfg in configs)
        code = 0
        for k, cfg in enumerate(configs):
            if len(configs) > 1:
                log.info("multirun job %d/%d: %s", k + 1, len(configs), " ".join(jobs[k]))
            code = max(code, script.job(cfg))
        return code
    except err_types as err:
        log.error("%s", err)
        return 2
    except BrokenPipeError:  # output piped into head & co.
        return 0


def dataclass_loader(schema, required: tuple[str, ...] = ()) -> Callable[[list[str]], Any]:
    """``load`` for scripts whose config is one dataclass (no config groups): dotlist overrides, checked.

    ``required`` keys have no default (``""`` / ``"???"`` in the schema) and must be given.
    """
    valid = valid_keys(schema)

    def load(overrides: list[str]):
        for item in overrides:
            key = item.split("=", 1)[0]
            if key not in valid:
                raise CliError(unknown_key_message(key, valid))
        try:
            merged = OmegaConf.merge(OmegaConf.structured(schema), OmegaConf.from_dotlist(overrides))
            missing = [k for k in required if str(OmegaConf.select(merged, k, default="")) in ("", "???")]
            if missing:
                raise CliError(f"missing {', '.join(k + '=' for k in missing)} (see --help)")
            return OmegaConf.to_object(merged)
        except CliError:
            raise
        except Exception as err:  # omegaconf: a value of the wrong type
            raise CliError(str(err).splitlines()[0]) from None

    return load
