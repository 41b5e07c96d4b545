"""SIGINT, SIGTERM and SIGHUP end a command the same way: the code being run is
interrupted by an exception, every ``finally`` and ``except BaseException`` on the way
out runs (a temporary output file beside the target is removed, the folder holding a
copy of a piped program is deleted, forked children are stopped), and the process
exits 128 + the signal's number (130, 143, 129), as a shell reports a process the
signal ended. Exit 1 stays reserved for internal errors.

Without this, SIGTERM and SIGHUP end Python at once (no cleanup), and click turns
Ctrl-C into "Aborted!" and exit 1.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading

#: the signals that stop a command with cleanup
SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))

_owner_pid: int | None = None  # the process whose handler raises (a forked child ends as by default)


class SignalExit(KeyboardInterrupt):
    """A signal stopped the command. A KeyboardInterrupt, so that code which cleans up on
    Ctrl-C cleans up the same way on SIGTERM and SIGHUP; ``exit_code`` is 128 + n."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = signum
        self.exit_code = 128 + signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


def exit_code(exc: KeyboardInterrupt) -> int:
    """The exit code of a command stopped by ``exc`` (a plain KeyboardInterrupt is SIGINT)."""
    return exc.exit_code if isinstance(exc, SignalExit) else 128 + signal.SIGINT


def signal_name(exc: KeyboardInterrupt) -> str:
    return exc.name if isinstance(exc, SignalExit) else "SIGINT"


def _handler(signum, frame) -> None:
    if os.getpid() != _owner_pid:
        # a child forked to correct or read part of a program: it holds no named file;
        # it ends as the signal ends a process, and its parent reports
        signal.signal(signum, signal.SIG_DFL)
        os.kill(os.getpid(), signum)
        return
    # the cleanup on the way out runs to its end: a second Ctrl-C or SIGTERM does not cut it short
    for s in SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    raise SignalExit(signum)


@contextlib.contextmanager
def stopping_cleanly():
    """Within the block, SIGINT, SIGTERM and SIGHUP raise :class:`SignalExit` in this
    process (in the main thread only, where Python runs handlers); the handlers in place
    before are restored after it."""
    global _owner_pid
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = {s: signal.getsignal(s) for s in SIGNALS}
    owner_before, _owner_pid = _owner_pid, os.getpid()
    try:
        for s in SIGNALS:
            if before[s] is not signal.SIG_IGN:  # nohup's SIGHUP, a background job's SIGINT: stay ignored
                signal.signal(s, _handler)
        yield
    finally:
        _owner_pid = owner_before
        for s, handler in before.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)


_busy = False  # a batch worker is correcting a file (see worker_init)


def worker_init() -> None:
    """Initializer of a batch worker process (``correct`` on several files with -j): a
    signal while it corrects a file raises (its temporary output is removed on the way
    out, see :func:`run_guarded`); while idle it ends the worker at once."""
    global _owner_pid
    _owner_pid = None
    for s in SIGNALS:
        signal.signal(s, _worker_handler)


def _worker_handler(signum, frame) -> None:
    if not _busy:
        os._exit(128 + signum)
    # the first signal stops the file; a second (the parent ending its workers) must not
    # interrupt the cleanup that removes the temporary output on the way out
    for s in SIGNALS:
        signal.signal(s, signal.SIG_IGN)
    raise SignalExit(signum)


def run_guarded(fn, *args):
    """``fn(*args)`` in a batch worker; stopped by a signal, the worker ends (exit 128 + n)
    once the cleanup on the way out has run."""
    global _busy
    _busy = True
    try:
        return fn(*args)
    except KeyboardInterrupt as exc:
        for s in SIGNALS:
            signal.signal(s, signal.SIG_IGN)
        os._exit(exit_code(exc))
    finally:
        _busy = False
