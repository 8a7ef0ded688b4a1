"""File modes for files written through a temporary file and a rename (maps, SLAM
sessions, trajectories): a crash never leaves half a file, and the result is as readable as
any other file the user writes."""

from __future__ import annotations

import os
import threading

__all__ = ["created_file_mode"]

_umask_lock = threading.Lock()


def _current_umask() -> int:
    try:  # Linux ≥ 4.7 reports it without changing it
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _umask_lock:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def created_file_mode() -> int:
    """The mode ``open(path, "w")`` would give a new file: 0o666 less the process umask.

    ``tempfile.mkstemp`` creates 0o600 files; a temporary file renamed over the target gets
    this mode first, so saved maps and sessions are as readable as any other file the user
    writes."""
    return 0o666 & ~_current_umask()
