"""Every checkpoint file docs/results.md and README quote exists, or the line says which commit holds it."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
QUOTED = re.compile(r"checkpoints/[A-Za-z0-9_/.-]+?/model_\d+\.pt")  # any depth: checkpoints/table1/<cell>/seed<k>/
IN_GIT = re.compile(r"git show ([0-9a-f]{7,40}):(checkpoints/[A-Za-z0-9_/.-]+?/model_\d+\.pt)")


def test_quoted_checkpoints_exist_or_name_their_commit():
    missing = []
    for doc in (ROOT / "docs" / "results.md", ROOT / "README.md"):
        for n, line in enumerate(doc.read_text().splitlines(), 1):
            kept = {path for _, path in IN_GIT.findall(line)}
            for path in QUOTED.findall(line):
                if not (ROOT / path).is_file() and path not in kept:
                    missing.append(f"{doc.name}:{n}: {path}")
    assert not missing, "quoted checkpoints that do not exist:\n" + "\n".join(missing)


def test_the_commits_named_for_removed_checkpoints_hold_them():
    for doc in (ROOT / "docs" / "results.md", ROOT / "README.md"):
        for commit, path in IN_GIT.findall(doc.read_text()):
            out = subprocess.run(["git", "cat-file", "-e", f"{commit}:{path}"], cwd=ROOT, capture_output=True)
            assert out.returncode == 0, f"{doc.name}: git show {commit}:{path} does not exist"
