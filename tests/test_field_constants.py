"""HumanoidPF's constants have one definition (cat.fields.FieldCfg): no config group or run key can fork them."""

from __future__ import annotations

from pathlib import Path

import pytest

from cat.learning.hydra_cfg import ConfigError, load_config
from cat.run.config import TrainCfg

REPO = Path(__file__).resolve().parents[1]


def test_no_field_config_group_or_key():
    assert not (REPO / "configs" / "field").exists()
    assert "field" not in TrainCfg.__dataclass_fields__
    for override in ("field=default", "field.eta=2.0"):
        with pytest.raises(ConfigError, match="field"):
            load_config([override])


def test_docs_do_not_claim_a_field_config():
    for doc in ("docs/fields.md", "README.md"):
        assert "configs/field" not in (REPO / doc).read_text(), doc
