"""Evaluation: the paper's trial protocol (§IV-A), defined once.

``metrics``: the success / DE / collision / fall rules (also used by the env's training log); ``trials``:
deterministic trial enumeration; ``runner``: one trial per env, no auto-reset; ``table``: Tables I and II
from a manifest; ``test_set``: the unseen Table II scenes. See docs/evaluation.md.
"""
