"""Whether bf16 autocast (``algo.mixed_precision``) can pay off on the machine a run trains on.

On a CPU, PyTorch's bf16 matmuls are fast only with native bf16 instructions (AMX-BF16 or AVX512-BF16). Without
them it emulates bf16 and the PPO update runs about ten times slower than in fp32 (measured on the project's AMD EPYC
machine, 2026-12-02: a 6,144-sample MLP forward/backward 33 s against 3.1 s; docs/benchmarks.md), so a run asking
for it there is warned once, with the fix.
"""

from __future__ import annotations

import logging
from pathlib import Path

log = logging.getLogger(__name__)

BF16_FLAGS = ("amx_bf16", "avx512_bf16")


def cpu_has_bf16(cpuinfo: str | None = None) -> bool:
    """True when the CPU flags (``/proc/cpuinfo``) name a native bf16 instruction set; True when unknown."""
    if cpuinfo is None:
        path = Path("/proc/cpuinfo")
        if not path.is_file():
            return True  # not Linux: cannot tell, do not warn
        cpuinfo = path.read_text(errors="replace")
    flags = {f for line in cpuinfo.splitlines() if line.startswith("flags") for f in line.split(":", 1)[1].split()}
    return not flags or any(f in flags for f in BF16_FLAGS)


def check_mixed_precision(enabled: bool, device: str, cpuinfo: str | None = None) -> bool:
    """Warn when bf16 autocast is asked for on a CPU without native bf16; returns whether it was warned."""
    if not enabled or not str(device).startswith("cpu") or cpu_has_bf16(cpuinfo):
        return False
    log.warning(
        "algo.mixed_precision=true on a CPU without AMX-BF16 / AVX512-BF16: bf16 is emulated and the PPO update runs "
        "~10x slower than fp32 here; set algo.mixed_precision=false"
    )
    return True
