"""Experiments as code: ``configs/experiment/<name>.yaml`` cells and tables, run by ``scripts/experiment.py``."""
