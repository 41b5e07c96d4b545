"""Writing output files safely: a temporary file beside the target, renamed at the end.

Nothing half-written is ever left under the target's name: on any error the temporary
file is removed and an existing file of that name stays as it was.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from postproc.errors import OutputError


def output_mode(path: Path) -> int:
    """Permissions for a new output file: those of the file it replaces, else 0666 less umask.

    ``mkstemp`` creates files readable by their owner only; a corrected program or a
    calibration must be readable as any ordinary file the user writes would be.
    """
    try:
        return path.stat().st_mode & 0o777
    except OSError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


@contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = ".tmp") -> Iterator[str]:
    """Yield a temporary path beside ``path``; rename it to ``path`` if the block succeeds."""
    target = Path(path)
    try:
        fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=suffix)
    except OSError as exc:
        raise _cannot_write(target, exc) from None
    os.close(fd)
    try:
        yield tmp
        os.chmod(tmp, output_mode(target))
        try:
            os.replace(tmp, target)
        except OSError as exc:
            raise _cannot_write(target, exc) from None
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _cannot_write(target: Path, exc: OSError) -> OutputError:
    """The error for an output that cannot be created where it was asked for."""
    if not target.parent.is_dir():
        return OutputError(f"cannot write the output: directory {str(target.parent)!r} does not exist",
                           path=str(target), hint="create the directory first, or give another output path")
    return OutputError(f"cannot write the output: {exc.strerror}", path=str(target),
                       hint="check the output path and its permissions")


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` (UTF-8, line endings as given) atomically to ``path``."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="") as fh:
        fh.write(text)


def atomic_write_texts(files: dict) -> None:
    """Write several files together: every temporary file is written first, then all are
    renamed, so a failure while writing leaves none of them (a set such as axis tables
    and their squareness file is never half new, half old)."""
    with ExitStack() as stack:
        for path, text in files.items():
            tmp = stack.enter_context(atomic_path(path))
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                fh.write(text)


def save_figure(fig, path: str | os.PathLike, **savefig_kwargs) -> None:
    """Save a matplotlib figure atomically and close it (figures are not kept open)."""
    import matplotlib.pyplot as plt

    suffix = Path(path).suffix or ".png"
    try:
        with atomic_path(path, suffix=suffix) as tmp:
            fig.savefig(tmp, **savefig_kwargs)
    finally:
        plt.close(fig)
