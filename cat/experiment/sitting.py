"""Which sitting (a ``scripts/experiment.py`` process) trains a unit: the record a sitting leaves in
``state.json`` while it trains one, and whether a record's sitting may still be running."""

from __future__ import annotations

import os
import socket
import time


def this_sitting(until: float | None) -> dict:
    """This process's record: host, pid and the sitting's end (Unix time, None: no budget)."""
    return {"host": socket.gethostname(), "pid": os.getpid(), "until": until}


def live_sitting(held: dict) -> str | None:
    """A ``"sitting"`` record (host, pid, end) -> who it is while that sitting may still run, else None (this
    process; a process gone from this host; another host's sitting whose end has passed)."""
    host, pid, until = held.get("host"), int(held.get("pid", 0)), held.get("until")
    if host == socket.gethostname():
        if pid == os.getpid():
            return None
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return None  # that sitting is gone (killed before it could release)
        except PermissionError:
            pass  # alive, another user's
    elif until is not None and until < time.time():
        return None
    end = "" if until is None else f" until {time.strftime('%H:%M', time.localtime(until))}"
    return f"the sitting of pid {pid} on {host}{end}"
