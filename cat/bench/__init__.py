"""Benchmarks, one module per ``scripts/bench.py`` case (sim, fields, train, eval, gen, scale, soak, live).

They sit above every product package (they time fields, terrain, physics, envs, eval, learning and deploy
together), so no product module imports them; results are in docs/benchmarks.md.
"""
