"""Build a scene dataset: ``python scripts/gen_scenes.py out=<dir> typical_variants=1 procedural=2 indoor=2 seed=0``.

Typical types × variants, procedural scenes over [difficulty_min, difficulty_max], indoor crops (embedded
procedural houses, or 3D-FRONT with ``front3d_dir=... future_dir=...``); one folder per scene, resumable,
fields precomputed per goal when ``cat.fields`` is available. Keys: ``cat.terrain.dataset.GenScenesCfg``.
"""

from __future__ import annotations

import logging
import sys
import time
from dataclasses import fields
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.config_store import ConfigStore
from hydra.core.global_hydra import GlobalHydra
from omegaconf import OmegaConf

from cat.terrain.dataset import GenScenesCfg, build_dataset
from cat.terrain.scene import SceneError

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"
log = logging.getLogger("gen_scenes")


def load_cfg(overrides: list[str]) -> GenScenesCfg:
    """Compose ``configs/gen_scenes.yaml`` + ``key=value`` overrides into a ``GenScenesCfg``."""
    valid = [f.name for f in fields(GenScenesCfg)]
    for item in overrides:
        if "=" not in item:
            raise ValueError(f"argument {item!r} is not key=value; valid keys: {', '.join(valid)}")
        key = item.split("=", 1)[0].lstrip("+~")
        if key not in valid:
            raise ValueError(f"unknown key {key!r}; valid keys: {', '.join(valid)}")
    ConfigStore.instance().store(name="gen_scenes_schema", node=GenScenesCfg)
    GlobalHydra.instance().clear()
    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base=None):
            cfg = compose(config_name="gen_scenes", overrides=overrides)
    except Exception as err:  # hydra's message names the bad key or value
        cause = f" ({err.__cause__})" if err.__cause__ else ""
        raise ValueError(f"bad configuration: {err}{cause}") from err
    finally:
        GlobalHydra.instance().clear()
    return OmegaConf.to_object(cfg)


def main(argv: list[str]) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        cfg = load_cfg(argv)
        t0 = time.perf_counter()
        index = build_dataset(cfg)
    except (ValueError, SceneError) as err:
        log.error("%s", err)
        return 2
    log.info("wrote %d scene folders under %s in %.1f s", len(index), cfg.out, time.perf_counter() - t0)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
