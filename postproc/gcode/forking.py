"""Child processes forked to read or correct a large program (``diff``'s readers,
``correct``'s parts): where they can be had, how they start and how they end."""

from __future__ import annotations

import multiprocessing
import signal
import sys
import warnings
from multiprocessing.process import BaseProcess


def available() -> bool:
    """Whether this process may fork children: Linux with the "fork" start method, not
    from a daemon process (a ``multiprocessing.Pool`` worker, which may have none)."""
    return (sys.platform == "linux" and "fork" in multiprocessing.get_all_start_methods()
            and not multiprocessing.current_process().daemon)


def start(child: BaseProcess) -> None:
    """Start a forked child. Python 3.12 and later warn of a fork in a process with
    threads (numpy's BLAS pool, idle here); the children run only this package's code."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=r".*multi-threaded, use of fork\(\)", category=DeprecationWarning)
        child.start()


def in_child() -> None:
    """Called first in a child: Ctrl-C is the parent's to handle (it stops its children),
    and the kernel ends the child when the parent ends (Linux's PR_SET_PDEATHSIG), since a
    parent killed outright (SIGKILL, SIGTERM) runs no cleanup that would stop it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass  # then it ends at its next word to the parent (the pipe is gone)
