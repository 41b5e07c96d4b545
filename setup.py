"""Build: the hot modules of the G-code lane compiled by mypyc, from their one source.

``pip install .`` (or ``-e .``) compiles the modules of ``COMPILED`` with mypyc, which the
build backend installs as a declared build requirement (pyproject.toml). The same source
runs uncompiled, with the same output, where they are not compiled:

- ``POSTPROC_PURE=1`` in the environment skips the compilation;
- a build that fails (no C compiler, no Python headers) is reported and skipped, and the
  install goes on with the pure modules.

``python3 -m postproc --version`` says which is in use.
"""

from __future__ import annotations

import os
import sys

from setuptools import setup
from setuptools.command.build_ext import build_ext

# Small, self-contained modules (each imports nothing of the package that is not also
# here), type-checked by mypy, which mypyc compiles only if they check.
COMPILED = [
    "postproc/gcode/scanner.py",
    "postproc/gcode/numfmt.py",
    "postproc/gcode/plainscan.py",
    "postproc/gcode/runwords.py",
    "postproc/gcode/fitcore.py",
    "postproc/gcode/hintcore.py",
]


class OptionalBuildExt(build_ext):
    """build_ext that leaves the pure modules in place when compiling fails."""

    def run(self) -> None:
        try:
            super().run()
        except Exception as exc:  # noqa: BLE001  (any failure: the pure modules stay)
            self._skip(exc)

    def build_extension(self, ext) -> None:  # type: ignore[no-untyped-def]
        try:
            super().build_extension(ext)
        except Exception as exc:  # noqa: BLE001
            self._skip(exc)

    reported = False

    def _skip(self, exc: BaseException) -> None:
        if not OptionalBuildExt.reported:
            OptionalBuildExt.reported = True
            print(f"postproc: the compiled core was not built ({exc}); the same modules run uncompiled",
                  file=sys.stderr)


def ext_modules() -> list:
    if os.environ.get("POSTPROC_PURE", "") not in ("", "0"):
        return []
    try:
        from mypyc.build import mypycify
    except ImportError:
        print("postproc: mypyc is not available; the modules run uncompiled", file=sys.stderr)
        return []
    try:
        return mypycify(COMPILED, opt_level="3", group_name="postproc")
    except BaseException as exc:  # noqa: BLE001  (mypyc exits on a type error)
        print(f"postproc: mypyc could not compile the core ({exc!r}); the modules run uncompiled",
              file=sys.stderr)
        return []


setup(ext_modules=ext_modules(), cmdclass={"build_ext": OptionalBuildExt})
