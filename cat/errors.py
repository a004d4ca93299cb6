"""Errors every layer may raise and every script reports the same way (a shared utility: imports nothing)."""

from __future__ import annotations


class CliError(ValueError):
    """A bad command line or configuration value: printed as one line, exit code 2."""


class SetupError(RuntimeError):
    """Something the machine must provide is missing (e.g. the robot model: ``MENAGERIE_ROOT``): printed as one
    line naming it and how to provide it, exit code 2, from every script."""
