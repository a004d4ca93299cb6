"""Compose the run config from ``configs/`` with hydra overrides (``task=flat sim=warp num_envs=16``).

The yaml files are validated against the dataclass schema (``TrainCfg``), so an unknown key or task is an
error that lists the valid ones instead of being silently ignored.
"""

from __future__ import annotations

from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.config_store import ConfigStore
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from cat.cli import CliError, unknown_key_message, valid_keys
from cat.run.config import TrainCfg

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs"


class ConfigError(CliError):
    """A bad command-line override or config file."""


def _options(group: str) -> list[str]:
    return sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))


def load_config(overrides: list[str], config_name: str = "train", schema=TrainCfg):
    """Compose ``configs/<config_name>.yaml`` + overrides into a ``schema`` dataclass instance."""
    if not CONFIG_DIR.is_dir():
        raise ConfigError(f"config folder not found: {CONFIG_DIR}")
    ConfigStore.instance().store(name=f"{config_name}_schema", node=schema)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override {item!r} is not key=value")
        key = item.split("=", 1)[0].lstrip("+~")
        groups = [p.name for p in CONFIG_DIR.iterdir() if p.is_dir()]
        if key in groups and item.split("=", 1)[1] not in _options(key):
            raise ConfigError(
                f"unknown {key} {item.split('=', 1)[1]!r}; valid {key} options: {', '.join(_options(key))}"
            )
        valid = valid_keys(schema())
        # keys inside mapping-valued fields (task.observations.<group>.terms) are checked by hydra against the schema
        inside = any(key.startswith(v + ".") for v in valid)
        if key not in valid and key not in groups and not inside:
            raise ConfigError(unknown_key_message(key, valid + groups))
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base=None):
            cfg = compose(config_name=config_name, overrides=list(overrides))
    except Exception as err:  # hydra's message names the override; its cause says what is wrong with it
        reason = err.__cause__ or err.__context__
        detail = f": {str(reason).splitlines()[0]}" if reason is not None and str(reason) else ""
        raise ConfigError(f"{str(err).splitlines()[0]}{detail}") from err
    finally:
        GlobalHydra.instance().clear()
    return OmegaConf.to_object(cfg)
