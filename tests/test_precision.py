"""The bf16 autocast warning follows the CPU's flags."""

from __future__ import annotations

from cat.learning.precision import check_mixed_precision, cpu_has_bf16

AMD = "processor : 0\nflags : fpu sse sse2 avx2 avx512f\n"
XEON = "processor : 0\nflags : fpu sse avx512f avx512_bf16 amx_bf16 amx_tile\n"


def test_bf16_warning_follows_the_cpu_flags(caplog):
    assert not cpu_has_bf16(AMD) and cpu_has_bf16(XEON)
    assert check_mixed_precision(True, "cpu", AMD)
    assert "algo.mixed_precision=false" in caplog.text
    assert not check_mixed_precision(True, "cpu", XEON)
    assert not check_mixed_precision(False, "cpu", AMD)
    assert not check_mixed_precision(True, "cuda:0", AMD)
