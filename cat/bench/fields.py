"""Fields benchmark (``python scripts/bench.py fields``): full rebuild vs a scikit-fmm/numpy reference,
and the 4096-env × 13-link query. Prints one line per case (the only stdout output). ``--device cuda:0`` builds
and queries on that device (timings synchronise it); the reference build always runs on the CPU."""

from __future__ import annotations

import argparse
import importlib.util
import logging
import time
from collections.abc import Callable

import numpy as np
import torch

from cat.fields.bank import FieldBank
from cat.fields.config import FieldCfg
from cat.fields.field import build_field
from cat.fields.grid import Grid
from cat.fields.scenes import TYPICAL_GOAL, TYPICAL_GRID, WINDOW_GRID, cluttered_window, hurdle_crouch

log = logging.getLogger(__name__)


def reference_build(occ: np.ndarray, grid: Grid, goal, cfg: FieldCfg) -> np.ndarray:
    """The released code's pipeline on the same occupancy: scikit-fmm SDF and geodesic, numpy gradient."""
    import skfmm

    h = grid.voxel
    sdf = skfmm.distance(np.where(occ, -0.5, 0.5) * h, dx=h)
    r0 = 1.5 * h
    phi = np.ma.MaskedArray(np.linalg.norm(grid.centers() - np.asarray(goal), axis=-1) - r0, occ)
    geo = np.ma.filled(skfmm.distance(phi, dx=h), np.inf) + r0
    dc = np.maximum(sdf, cfg.d_min)
    u_rep = np.where(sdf < cfg.d0, 0.5 * cfg.xi * (1.0 / dc - 1.0 / cfg.d0) ** 2, 0.0)
    u = cfg.eta * np.where(np.isfinite(geo), geo, geo[np.isfinite(geo)].max()) + u_rep
    return -np.stack(np.gradient(u, h), axis=-1)


def device_sync(device: str | torch.device) -> Callable[[], None]:
    """What waits for ``device``'s queued work before a clock is read: ``torch.cuda.synchronize``, or nothing."""
    return torch.cuda.synchronize if torch.device(device).type == "cuda" else (lambda: None)


def median_ms(fn, repeat: int, device: str | torch.device = "cpu") -> float:
    """Median wall-clock ms of ``fn()`` over ``repeat`` calls; on CUDA each call is synchronised, so the figure
    is the work's, not the launch's."""
    sync = device_sync(device)
    ts = []
    for _ in range(repeat):
        sync()
        t0 = time.perf_counter()
        fn()
        sync()
        ts.append((time.perf_counter() - t0) * 1e3)
    return float(np.median(ts))


def bench_device(device: str) -> str:
    """``device`` checked for the benches: 'cpu' or a CUDA device torch and Warp both see (else one clear line)."""
    if device == "cpu":
        return device
    from cat.envs.sim.warp_backend import resolve_device

    try:
        name = resolve_device(device)
    except (RuntimeError, ValueError) as err:
        raise SystemExit(f"--device {device}: {err}") from None
    if not torch.cuda.is_available():
        raise SystemExit(f"--device {device}: this torch build has no CUDA (torch {torch.__version__})")
    return name


def bench_build(name: str, occ: np.ndarray, grid: Grid, goal, repeat: int, device: str = "cpu") -> None:
    cfg = FieldCfg()
    build_field(occ, grid, goal, cfg, device=device)  # compile / load kernels, allocate workspaces
    ours = median_ms(lambda: build_field(occ, grid, goal, cfg, device=device), repeat, device)
    nx, ny, nz = grid.shape
    if importlib.util.find_spec("skfmm") is None:  # scikit-fmm ships no cp312 wheel: absent on the lent GPU
        log.warning("scikit-fmm is not installed: the reference build is not timed")
        tail = "reference_ms=n/a"
    else:
        ref = median_ms(lambda: reference_build(occ, grid, goal, cfg), max(1, repeat // 2))
        tail = f"reference_ms={ref:.1f} speedup={ref / ours:.2f}"
    print(f"case={name} grid={nx}x{ny}x{nz} build_ms={ours:.1f} {tail} device={device}", flush=True)


def bench_query(envs: int, links: int, n_fields: int, repeat: int, name: str = "query", device: str = "cpu") -> None:
    """Bank of ``n_fields`` typical-scene fields (different goals; 4.5 MB each); each env's links within
    ±0.35 m (±0.7 m in z) of its pelvis, envs spread over the course and over the fields. The query is
    a memory-bound gather: a bank larger than the caches is the realistic training case."""
    occ = hurdle_crouch()
    rng = np.random.default_rng(0)
    goals = [(2.0, y, 0.75) for y in np.linspace(-0.6, 0.6, n_fields)]
    bank = FieldBank.from_fields([build_field(occ, TYPICAL_GRID, g) for g in goals], device=device)
    idx = torch.as_tensor(rng.integers(0, n_fields, envs), dtype=torch.int32)
    root = torch.as_tensor(rng.uniform([-0.3, -0.8, 0.7], [2.3, 0.8, 0.8], (envs, 1, 3)), dtype=torch.float32)
    pts = root + torch.as_tensor(rng.uniform(-0.35, 0.35, (envs, links, 3)), dtype=torch.float32) * torch.tensor(
        [1.0, 1.0, 2.0]
    )
    idx, pts = idx.to(device), pts.to(device)
    out = bank.query(idx, pts)
    ms = median_ms(lambda: bank.query(idx, pts, out), repeat, device)
    extra = "" if name == "query" else f" fields={n_fields}"
    print(f"case={name} envs={envs} links={links}{extra} query_ms={ms:.2f} device={device}", flush=True)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(prog="bench.py fields", description=__doc__)
    p.add_argument("--repeat", type=int, default=7, help="timed repetitions per case (median reported)")
    p.add_argument("--envs", type=int, default=4096)
    p.add_argument("--fields", type=int, default=8, help="fields in the query bank")
    p.add_argument("--device", default="cpu", help="cpu or cuda[:i]: where fields are built and queried")
    p.add_argument("--precision", action="store_true", help="also case=bank_precision (float16, compact vs float32)")
    args = p.parse_args(argv)
    import warp as wp

    wp.config.log_level = getattr(wp, "LOG_WARNING", wp.config.log_level)  # keep stdout to result lines
    torch.set_num_threads(1)
    dev = bench_device(args.device)
    bench_build("typical", hurdle_crouch(), TYPICAL_GRID, TYPICAL_GOAL, args.repeat, dev)
    bench_build("window", cluttered_window(), WINDOW_GRID, (0.0, 0.0, 0.75), args.repeat, dev)
    bench_query(args.envs, 13, args.fields, args.repeat * 5, device=dev)
    bench_query(args.envs, 13, 1, args.repeat * 5, name="query_1field", device=dev)
    if args.precision:
        precision_case()


def with_goals(scene, n: int):
    """The scene with exactly ``n`` goals: typical ones across the far end, others cycled."""
    if scene.kind in ("procedural", "indoor"):
        scene.goals = np.resize(scene.goals, (n, 3))
    else:
        g = scene.goals[0]
        scene.goals = np.c_[np.full(n, g[0]), np.linspace(-0.6, 0.6, n), np.full(n, g[2])]
    return scene


def precision_case(goals: int = 3) -> None:
    """``case=bank_precision``: float16 and compact storage against float32 on a typical, a procedural and an
    indoor scene with ``goals`` goals each (docs/fields.md)."""
    from cat.envs.scene_set import scene_fields
    from cat.terrain import make_indoor, make_procedural, make_typical

    scenes = [make_typical("hurdle-crouch", 0.5, 0), make_procedural(0.6, 1), make_indoor(2)]
    fields = [scene_fields(with_goals(s, goals), None, None) for s in scenes]
    for dtype in ("float16", "compact"):
        r = bank_precision(fields, dtype=dtype)
        print(f"case=bank_precision dtype={dtype} " + " ".join(f"{k}={v:.3g}" for k, v in r.items()), flush=True)


def bank_precision(
    scenes: list, points_per_field: int = 20000, seed: int = 0, dtype: str = "float16"
) -> dict[str, float]:
    """Error of a ``dtype`` bank (float16 or compact) against the float32 bank of the same ``SceneFields`` at
    random points in each field's grid: |Δd| and |Δ∇d| (m, unitless), the angle between F directions (degrees,
    where |F| > 1e-3) and |Δ|F||/|F|. Returns max and 99th percentile of each."""
    rng = np.random.default_rng(seed)
    b32 = FieldBank.from_scenes(scenes, dtype="float32")
    b16 = FieldBank.from_scenes(scenes, dtype=dtype)
    idx = torch.arange(b32.num_fields, dtype=torch.int32).repeat_interleave(points_per_field // 100)
    lo, hi = b32.field_bounds(idx)
    pts = lo[:, None] + torch.as_tensor(rng.uniform(0, 1, (len(idx), 100, 3)), dtype=torch.float32) * (hi - lo)[:, None]
    a, b = b32.query(idx, pts), b16.query(idx, pts)
    dd = (a.sdf - b.sdf).abs().flatten()
    dg = (a.grad_sdf - b.grad_sdf).norm(dim=-1).flatten()
    fa, fb = a.force.reshape(-1, 3), b.force.reshape(-1, 3)
    na, nb = fa.norm(dim=-1), fb.norm(dim=-1)
    ok = na > 1e-3
    cos = ((fa * fb).sum(-1)[ok] / (na[ok] * nb[ok]).clamp_min(1e-12)).clamp(-1, 1)
    ang = torch.rad2deg(torch.acos(cos.double()))
    rel = ((na - nb).abs() / na)[ok]
    out = {}
    for name, v in (("sdf_m", dd), ("grad_sdf", dg), ("force_deg", ang), ("force_rel", rel)):
        out[f"{name}_max"] = float(v.max())
        out[f"{name}_p99"] = float(torch.quantile(v.double()[: 1 << 24], 0.99))
    return out


if __name__ == "__main__":
    main()
