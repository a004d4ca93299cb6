"""Errors every layer may raise and every script reports the same way (a shared utility: imports nothing)."""

from __future__ import annotations


class CliError(ValueError):
    """A bad command line or configuration value: printed as one line, exit code 2."""
