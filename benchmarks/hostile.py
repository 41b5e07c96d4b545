"""Hostile-input survey: run a checkout's CLI on >= 150 hostile or broken inputs
and classify each outcome.

Every case is built in code in a fresh working directory (no large files are kept):
malformed G-code, each dialect's odd constructs, unbounded loops, huge helix turns, deep
and long expressions, 400-digit coordinates, NaN/inf in the numeric options of every
command, calibrations broken every way in every format the project reads (calibration
JSON, machine JSON, point measurements, axis error tables, squareness, ISO 230-2 runs,
TF5280 ISG), tool tables, subroutine lookups escaping --subroutine-path, over-long lines
per dialect, M62/M67 on split moves, already-corrected programs, binary junk, empty
files, CR-only line endings, unwritable outputs, /dev/full, signals mid-run, piped stdin.

Each case runs ``python3 -m postproc ...`` with ``PYTHONPATH=ROOT``, its cwd a fresh
temporary folder, ``TMPDIR`` another fresh one, a timeout (60 s; 30 s for cases that are
expected to run unbounded) and an address-space limit of 3 GB. Outcomes:

  ok              exit 0 and sane output (the case's check passed)
  refused         documented non-zero exit (the checkout's EXIT_* codes in errors.py other
                  than 0 and 1; 2-6 on 5b3c58d) with path:line:col or a clear message
  refused-no-col  refusal naming a program line (path:line:) without a column
  internal        traceback, "internal error", or exit 1
  warning-leak    RuntimeWarning or other warning text on stderr
  hang            timeout
  memory          MemoryError, or killed (SIGKILL/SIGSEGV, the address-space limit)
  leftover        temporary files left (beside the output, in TMPDIR), or an output
                  written by a refused run
  bad-exit        a signal not mapped to 128+n (or to death by that signal)
  silent-wrong    exit 0 where a refusal is required (a NaN option accepted, a
                  subroutine read outside --subroutine-path, an output line over the
                  dialect's limit, an M62 without its P word, ...)

A whole run (397 cases) took 811 s on the 5b3c58d checkout on a loaded 2-core machine,
13 of them hangs at 30 s each. hostile_before.json / hostile_before.txt hold that run.

Usage::

    python3 benchmarks/hostile.py --root /work/wt/before --json benchmarks/hostile_before.json
    python3 benchmarks/hostile.py --root . -k nan          # only cases whose name holds 'nan'
    python3 benchmarks/hostile.py --compare benchmarks/hostile_before.json after.json
    python3 benchmarks/hostile.py --list
"""

from __future__ import annotations

import argparse
import json
import os
import random
import re
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

TIMEOUT_S = 60
HANG_TIMEOUT_S = 30
AS_LIMIT = 3_000_000_000

OUTCOMES = ("ok", "refused", "refused-no-col", "internal", "warning-leak", "hang", "memory",
            "leftover", "bad-exit", "silent-wrong", "setup-failed")

SIMPLE = "G21 G90\nG0 X10 Y10 Z10\nG1 X100 Y100 Z20 F500\nG1 X150 Y60\nM2\n"
ARC = "G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 F500\nG1 X150 Y150\nM2\n"


# ---------------------------------------------------------------------------------- cases

@dataclass
class Ctx:
    """What a case's setup sees: its working folder, the checkout, and the CLI for pre-steps."""

    work: Path
    root: Path
    env: dict
    pre_failed: list = field(default_factory=list)

    def write(self, name: str, text: str | bytes) -> str:
        p = self.work / name
        p.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(text, bytes):
            p.write_bytes(text)
        else:
            p.write_bytes(text.encode("utf-8"))
        return name

    def cal(self, name: str = "s500_static.json") -> str:
        """A bundled calibration (copied from the checkout under test)."""
        src = self.root / "calibrations" / name
        shutil.copy(src, self.work / name)
        return name

    def cal_json(self, name: str = "s500_static.json") -> dict:
        return json.loads((self.root / "calibrations" / name).read_text())

    def machine(self) -> str:
        for n in ("s500.machine.json", "s500_tables.csv", "s500_tables_squareness.csv"):
            shutil.copy(self.root / "calibrations" / n, self.work / n)
        return "s500.machine.json"

    def sample(self, name: str) -> str:
        shutil.copy(self.root / "samples" / name, self.work / Path(name).name)
        return Path(name).name

    def cli(self, *args: str) -> subprocess.CompletedProcess:
        """A pre-step through the same CLI (e.g. correct once before correcting again)."""
        r = subprocess.run([sys.executable, "-m", "postproc", *args], cwd=self.work, env=self.env,
                           capture_output=True, timeout=TIMEOUT_S, preexec_fn=_limits)
        if r.returncode != 0:
            self.pre_failed.append(f"pre-step {' '.join(args)} exit {r.returncode}: "
                                   f"{r.stderr.decode(errors='replace').strip()[:200]}")
        return r


@dataclass
class Case:
    name: str
    setup: Callable[[Ctx], list]  # returns argv after 'python3 -m postproc'
    must_refuse: bool = False  # exit 0 is silent-wrong
    check: Callable[[Ctx, str], str | None] | None = None  # on exit 0: None if sane, else why not
    stdin: Callable[[Ctx], bytes] | None = None
    stdin_path: str | None = None  # feed stdin from this device/file path (e.g. /dev/zero)
    timeout: int = TIMEOUT_S
    signal: int | None = None  # send this signal once the run has started writing
    note: str = ""


CASES: list[Case] = []


def case(name, must_refuse=False, check=None, stdin=None, timeout=TIMEOUT_S, sig=None, stdin_path=None, note=""):
    def deco(fn):
        CASES.append(Case(name, fn, must_refuse, check, stdin, stdin_path, timeout, sig, note))
        return fn
    return deco


def add(name, setup, **kw):
    case(name, **kw)(setup)


def correct_prog(prog, *extra, cal="s500_static.json", fname="p.nc"):
    """A setup: write ``prog`` and correct it to out.nc."""
    def setup(c: Ctx):
        f = c.write(fname, prog)
        return ["correct", f, "-c", c.cal(cal), "-o", "out.nc", *extra]
    return setup


def out_exists(c: Ctx, _err: str) -> str | None:
    p = c.work / "out.nc"
    if not p.exists() or p.stat().st_size == 0:
        return "exit 0 but out.nc missing or empty"
    return None


# -- malformed G-code -------------------------------------------------------------------

rng = random.Random(32)
JUNK = bytes(rng.randrange(256) for _ in range(4000))

add("gcode-empty-file", correct_prog(""), must_refuse=True)
add("gcode-whitespace-only", correct_prog("   \n\t\n\n"), must_refuse=True)
add("gcode-comments-only", correct_prog("(just a comment)\n; another\n"), must_refuse=True)
add("gcode-percent-only", correct_prog("%\n%\n"), must_refuse=True)
add("gcode-binary-junk", correct_prog(JUNK), must_refuse=True)
add("gcode-nul-bytes", correct_prog("G21 G90\nG0 X10\x00 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-invalid-utf8", correct_prog(b"G21 G90\nG0 X10 Y10 Z10 (\xff\xfe\xc3)\nM2\n"), check=out_exists)
add("gcode-utf16-bom", correct_prog("\ufeffG21 G90\nG0 X10 Y10 Z10\nM2\n".encode("utf-16")), must_refuse=True)
add("gcode-utf8-bom", correct_prog("\ufeff" + SIMPLE), check=out_exists)
add("gcode-cr-only-endings", correct_prog(SIMPLE.replace("\n", "\r")), check=out_exists)
add("gcode-mixed-crlf-lf", correct_prog("G21 G90\r\nG0 X10 Y10 Z10\nG1 X100 Y100 Z20 F500\r\nM2\n"), check=out_exists)
add("gcode-no-final-newline", correct_prog(SIMPLE.rstrip("\n")), check=out_exists)
add("gcode-letter-without-number", correct_prog("G21 G90\nG0 X Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-double-decimal-point", correct_prog("G21 G90\nG0 X1.2.3 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-double-sign", correct_prog("G21 G90\nG0 X--5 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-exponent-number", correct_prog("G21 G90\nG0 X1e3 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-unknown-g-code", correct_prog("G21 G90\nG999 X10\nM2\n"), must_refuse=True)
add("gcode-unclosed-comment", correct_prog("G21 G90\nG0 X10 Y10 Z10 (no end\nM2\n"), must_refuse=True)
add("gcode-nested-comment", correct_prog("G21 G90\nG0 X10 Y10 Z10 (a (b) c)\nM2\n"))
add("gcode-duplicate-axis-word", correct_prog("G21 G90\nG0 X10 X20 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-two-motion-codes", correct_prog("G21 G90\nG0 G1 X10 Y10 Z10 F100\nM2\n"), must_refuse=True)
add("gcode-g1-without-feed", correct_prog("G21 G90 G94\nG1 X10 Y10 Z10\nM2\n"))
add("gcode-arc-zero-radius", correct_prog("G21 G90 G17\nG0 X10 Y10 Z10\nG2 X20 Y10 R0 F100\nM2\n"), must_refuse=True)
add("gcode-arc-ij-zero", correct_prog("G21 G90 G17\nG0 X10 Y10 Z10\nG2 X20 Y10 I0 J0 F100\nM2\n"), must_refuse=True)
add("gcode-arc-radius-mismatch", correct_prog("G21 G90 G17\nG0 X10 Y10 Z10\nG2 X100 Y10 I5 J0 F100\nM2\n"), must_refuse=True)
add("gcode-arc-r-too-small", correct_prog("G21 G90 G17\nG0 X10 Y10 Z10\nG2 X100 Y10 R5 F100\nM2\n"), must_refuse=True)
add("gcode-arc-p0", correct_prog("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 P0 F500\nM2\n"), must_refuse=True)
add("gcode-arc-p-negative", correct_prog("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 P-5 F500\nM2\n"), must_refuse=True)
add("gcode-arc-p-fraction", correct_prog("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 P2.5 F500\nM2\n"), must_refuse=True)
add("gcode-helix-p100000", correct_prog("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 Z20 I50 J0 P100000 F500\nM2\n"),
    timeout=HANG_TIMEOUT_S, note="huge helix P word")
add("gcode-helix-p1e9", correct_prog("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 Z20 I50 J0 P1000000000 F500\nM2\n"),
    timeout=HANG_TIMEOUT_S)
add("gcode-400-digit-coordinate", correct_prog("G21 G90\nG0 X" + "9" * 400 + " Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-400-digit-coordinate-clamp", correct_prog("G21 G90\nG0 X" + "9" * 400 + " Y10 Z10\nM2\n",
                                                     "--extrapolate", "clamp"), must_refuse=True)
add("gcode-400-digit-coordinate-linear", correct_prog("G21 G90\nG0 X" + "9" * 400 + " Y10 Z10\nM2\n",
                                                      "--extrapolate", "linear"), must_refuse=True)
add("gcode-400-decimal-digits", correct_prog("G21 G90\nG0 X10." + "3" * 400 + " Y10 Z10\nM2\n"), check=out_exists)
add("gcode-400-digit-feed", correct_prog("G21 G90\nG0 X10 Y10 Z10\nG1 X20 F" + "9" * 400 + "\nM2\n"))
add("gcode-400-digit-tool-number", correct_prog("G21 G90\nT" + "9" * 400 + " M6\nG0 X10 Y10 Z10\nM2\n"))
add("gcode-400-digit-n-number", correct_prog("G21 G90\nN" + "9" * 400 + " G0 X10 Y10 Z10\nM2\n"))
add("gcode-100k-char-comment-line", correct_prog("G21 G90\nG0 X10 Y10 Z10 (" + "a" * 100_000 + ")\nM2\n"),
    must_refuse=True)
add("gcode-1m-char-line", correct_prog("G21 G90\nG0 X10 Y10 Z10 " + "G90 " * 250_000 + "\nM2\n"), must_refuse=True)
add("gcode-outside-volume", correct_prog("G21 G90\nG0 X1000 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-lowercase", correct_prog(SIMPLE.lower()), check=out_exists)
add("gcode-no-spaces", correct_prog(SIMPLE.replace(" ", "")), check=out_exists)
add("gcode-comma-decimal", correct_prog("G21 G90\nG0 X10,5 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-inch-huge", correct_prog("G20 G90\nG0 X1000 Y10 Z10\nM2\n"), must_refuse=True)
add("gcode-g5-spline", correct_prog("G21 G90 G17\nG0 X10 Y10 Z10\nG5 I10 J10 P10 Q-10 X100 Y100 F300\nM2\n"))
add("gcode-g5-degenerate", correct_prog("G21 G90 G17\nG0 X10 Y10 Z10\nG5 I0 J0 P0 Q0 X10 Y10 F300\nM2\n"))
add("gcode-million-moves-cap", correct_prog("G21 G90\nG0 X10 Y10 Z10\nG1 F500\n"
                                            + "".join(f"X{10 + (i % 200)} Y{10 + (i * 7) % 200}\n" for i in range(60_000))
                                            + "M2\n", "-j", "1"), timeout=HANG_TIMEOUT_S, check=out_exists,
    note="60k moves, one process")

# -- expressions and parameters ----------------------------------------------------------

add("expr-5000-deep", correct_prog("G21 G90\n#1=" + "[" * 5000 + "1" + "]" * 5000 + "\nG0 X#1 Y10 Z10\nM2\n",
                                   "--dialect", "linuxcnc"), must_refuse=True)
add("expr-100k-term-sum", correct_prog("G21 G90\n#1=[" + "+".join(["1"] * 100_000) + "]\nG0 X#1 Y10 Z10\nM2\n",
                                       "--dialect", "linuxcnc"), must_refuse=True)
add("expr-divide-by-zero", correct_prog("G21 G90\n#1=[1/0]\nG0 X#1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-sqrt-negative", correct_prog("G21 G90\n#1=[SQRT[-1]]\nG0 X#1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-acos-2", correct_prog("G21 G90\n#1=[ACOS[2]]\nG0 X#1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-exp-overflow", correct_prog("G21 G90\nG0 X[EXP[1000]] Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-power-overflow", correct_prog("G21 G90\n#1=[10**400]\nG0 X#1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-mul-overflow", correct_prog("G21 G90\n#1=[" + "9" * 300 + "*" + "9" * 300 + "]\nG0 X[#1-#1] Y10 Z10\nM2\n",
                                      "--dialect", "linuxcnc"), must_refuse=True)
add("expr-undefined-parameter", correct_prog("G21 G90\nG0 X#77 Y10 Z10\nM2\n", "--dialect", "linuxcnc"))
add("expr-parameter-index-huge", correct_prog("G21 G90\n#99999999=1\nG0 X10 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-parameter-index-negative", correct_prog("G21 G90\n#-1=5\nG0 X10 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-indirect-parameter", correct_prog("G21 G90\n#1=2\n#2=30\nG0 X##1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    check=out_exists)
add("expr-bracketed-literal", correct_prog("G21 G90\nG0 X[0] Y[10] Z[10]\nG1 X[20] F100\nM2\n", "--dialect", "linuxcnc"),
    check=out_exists)
add("expr-unbalanced-bracket", correct_prog("G21 G90\n#1=[[1+2]\nG0 X#1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-unknown-function", correct_prog("G21 G90\n#1=[FOO[2]]\nG0 X#1 Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-named-undefined", correct_prog("G21 G90\nG0 X#<nowhere> Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-ini-parameter", correct_prog("G21 G90\nG0 X#<_ini[axis_x]max_limit> Y10 Z10\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("expr-atan-zero-zero", correct_prog("G21 G90\nG0 X[ATAN[0]/[0]] Y10 Z10\nM2\n", "--dialect", "linuxcnc"))
add("expr-mod-zero", correct_prog("G21 G90\nG0 X[10 MOD 0] Y10 Z10\nM2\n", "--dialect", "linuxcnc"), must_refuse=True)
add("expr-fanuc-macro-div-zero", correct_prog("%\nO1000\nG21 G90\n#1=1/0\nG0 X#1 Y10 Z10\nM30\n%\n",
                                              "--dialect", "fanuc"), must_refuse=True)
add("expr-fanuc-incomplete", correct_prog("%\nO1000\nG21 G90\n#1=#2+\nG0 X10 Y10 Z10\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True)

# -- loops and subprograms ---------------------------------------------------------------

LOOP_MOVE = "G21 G90\nG0 X10 Y10 Z10\no100 while [1]\nG1 X20 F100\nG1 X10\no100 endwhile\nM2\n"
add("loop-oword-while-1-move", correct_prog(LOOP_MOVE, "--dialect", "linuxcnc"), must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("loop-oword-while-1-empty", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 while [1]\no100 endwhile\nM2\n",
                                             "--dialect", "linuxcnc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-oword-do-while-1", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 do\nG1 X20 F100\nG1 X10\no100 while [1]\nM2\n",
                                          "--dialect", "linuxcnc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-oword-nested-repeat", correct_prog(
    "G21 G90\nG0 X10 Y10 Z10\no1 repeat [100000]\no2 repeat [100000]\nG1 X20 F100\nG1 X10\no2 endrepeat\n"
    "o1 endrepeat\nM2\n", "--dialect", "linuxcnc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-oword-repeat-negative", correct_prog("G21 G90\nG0 X10 Y10 Z10\no1 repeat [-1]\nG1 X20 F100\no1 endrepeat\nM2\n",
                                               "--dialect", "linuxcnc"))
add("loop-oword-repeat-nan", correct_prog("G21 G90\nG0 X10 Y10 Z10\no1 repeat [SQRT[-1]]\nG1 X20 F100\no1 endrepeat\nM2\n",
                                          "--dialect", "linuxcnc"), must_refuse=True)
add("loop-oword-endwhile-alone", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 endwhile\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
# M2 inside a block never closed ends the program before its end is looked for: rs274 runs
# these two (exit 0, the same moves), so they are corrected as it runs them. A file that
# ends inside the open block (no M2, no closing %) is refused, as rs274 refuses it.
add("loop-oword-while-unclosed", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 while [#1 LT 3]\nG1 X20 F100\nM2\n",
                                              "--dialect", "linuxcnc"), check=out_exists,
    note="rs274 runs it: M2 ends the program inside the loop")
add("loop-oword-if-unclosed", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 if [1]\nG1 X20 F100\nM2\n",
                                           "--dialect", "linuxcnc"), check=out_exists,
    note="rs274 runs it: M2 ends the program inside the if")
add("loop-oword-while-unclosed-eof", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 while [#1 LT 3]\nG1 X20 F100\n",
                                                  "--dialect", "linuxcnc"), must_refuse=True)
add("loop-oword-if-unclosed-eof", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 if [1]\nG1 X20 F100\n",
                                               "--dialect", "linuxcnc"), must_refuse=True)
add("loop-oword-while-counter-endless", correct_prog(
    "G21 G90\nG0 X10 Y10 Z10\n#1=0\no100 while [#1 GE 0]\n#1=[#1+1]\no100 endwhile\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True, timeout=HANG_TIMEOUT_S, note="each pass changes #1: only the iteration bound stops it")
add("loop-oword-break-outside", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 break\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("loop-oword-mismatched-labels", correct_prog("G21 G90\nG0 X10 Y10 Z10\no100 while [#1 LT 3]\n#1=[#1+1]\no200 endwhile\nM2\n",
                                                 "--dialect", "linuxcnc"), must_refuse=True)
add("loop-oword-sub-recursion", correct_prog("o<rec> sub\nG1 X20 F100\no<rec> call\no<rec> endsub\nG21 G90\nG0 X10 Y10 Z10\n"
                                             "o<rec> call\nM2\n", "--dialect", "linuxcnc"), must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("loop-oword-call-missing", correct_prog("G21 G90\nG0 X10 Y10 Z10\no<nothere> call\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)
add("loop-fanuc-while-do-end", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\n#1=1\nWHILE [#1 EQ 1] DO1\nG1 X20 F100\n"
                                            "G1 X10\nEND1\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-fanuc-goto-back", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nN10 G1 X20 F100\nG1 X10\nGOTO 10\nM30\n%\n",
                                         "--dialect", "fanuc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-fanuc-if-goto", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\n#1=0\nN10 G1 X20 F100\nG1 X10\n"
                                       "IF [#1 EQ 0] GOTO 10\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-fanuc-goto-missing", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nGOTO 999\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True)
add("loop-fanuc-goto-huge-n", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nGOTO " + "9" * 50 + "\nM30\n%\n",
                                           "--dialect", "fanuc"), must_refuse=True)
add("loop-fanuc-do-without-end", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nWHILE [#1 LT 3] DO1\n#1=#1+1\nM30\n%\n",
                                              "--dialect", "fanuc"), must_refuse=True)
add("loop-fanuc-end-without-do", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nEND1\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True)
add("loop-fanuc-do-99", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nWHILE [#1 LT 3] DO99\n#1=#1+1\nEND99\nM30\n%\n",
                                     "--dialect", "fanuc"), must_refuse=True)
FANUC_SUB = "O2000\nG1 X20 F100\nG1 X10\nM99\n"
add("loop-m98-l99999999", correct_prog(f"%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM98 P2000 L99999999\nM30\n{FANUC_SUB}%\n",
                                       "--dialect", "fanuc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-m98-nested-repeats", correct_prog(
    "%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM98 P2000 L9999\nM30\nO2000\nM98 P3000 L9999\nM99\nO3000\nM98 P4000 L9999\nM99\n"
    "O4000\nG1 X20 F100\nG1 X10\nM99\n%\n", "--dialect", "fanuc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-m98-recursion", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM98 P2000\nM30\nO2000\nG1 X20 F100\nM98 P2000\nM99\n%\n",
                                       "--dialect", "fanuc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-m98-missing", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM98 P7777\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True)
add("loop-m99-in-main", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nG1 X20 F100\nM99\n%\n", "--dialect", "fanuc"),
    timeout=HANG_TIMEOUT_S)
add("loop-haas-m97-local", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM97 P100 L99999999\nM30\nN100 G1 X20 F100\nM99\n%\n",
                                        "--dialect", "haas"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-haas-m98-l0", correct_prog(f"%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM98 P2000 L0\nM30\n{FANUC_SUB}%\n", "--dialect", "haas"))
add("loop-mach3-m98-l99999999", correct_prog(f"G21 G90\nG0 X10 Y10 Z10\nM98 P2000 L99999999\nM30\n{FANUC_SUB}",
                                             "--dialect", "mach3"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("loop-fanuc-g65-macro-call", correct_prog("%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nG65 P9010 A1 B2\nM30\n%\n", "--dialect", "fanuc"),
    must_refuse=True)


# -- subroutine path escapes -------------------------------------------------------------

def sub_escape(kind):
    def setup(c: Ctx):
        (c.work / "subs").mkdir()
        c.write("subs/ok.ngc", "o<ok> sub\nG1 X30 F100\no<ok> endsub\nM2\n")
        outside = c.work / "outside"
        outside.mkdir()
        name = {"absolute": str(outside / "x"), "dotdot": "../outside/x", "slash": "./../outside/x"}[kind]
        # the file outside the path defines the subroutine under the name it is called by
        c.write("outside/x.ngc", f"o<{name}> sub\nG1 X40 F100\no<{name}> endsub\nM2\n")
        f = c.write("p.ngc", f"G21 G90\nG0 X10 Y10 Z10\no<{name}> call\nM2\n")
        return ["correct", f, "-c", c.cal(), "-o", "out.nc", "--dialect", "linuxcnc", "--subroutine-path", "subs"]
    return setup


add("sub-escape-absolute", sub_escape("absolute"), must_refuse=True, note="o</abs/x> call")
add("sub-escape-dotdot", sub_escape("dotdot"), must_refuse=True, note="o<../outside/x> call")
add("sub-escape-inner-dotdot", sub_escape("slash"), must_refuse=True)


def sub_ok(c: Ctx):
    (c.work / "subs").mkdir()
    c.write("subs/ok.ngc", "o<ok> sub\nG1 X30 F100\no<ok> endsub\nM2\n")
    f = c.write("p.ngc", "G21 G90\nG0 X10 Y10 Z10\no<ok> call\nM2\n")
    return ["correct", f, "-c", c.cal(), "-o", "out.nc", "--dialect", "linuxcnc", "--subroutine-path", "subs"]


add("sub-path-legit-call", sub_ok, check=out_exists)
add("sub-path-missing-dir", correct_prog("G21 G90\nG0 X10 Y10 Z10\no<ok> call\nM2\n", "--dialect", "linuxcnc",
                                         "--subroutine-path", "nowhere"), must_refuse=True)

# -- dialect odd constructs --------------------------------------------------------------

ODD = {
    "grbl-dollar-home": ("grbl", "$H\nG21 G90\nG0 X10 Y10 Z10\nM2\n"),
    "grbl-jog": ("grbl", "G21 G90\nG0 X10 Y10 Z10\n$J=G91 X10 F100\nM2\n"),
    "grbl-settings-dump": ("grbl", "$$\nG21 G90\nG0 X10 Y10 Z10\nM2\n"),
    "grbl-probe-g38": ("grbl", "G21 G90\nG0 X10 Y10 Z10\nG38.2 Z-10 F50\nM2\n"),
    "grbl-semicolon-comment": ("grbl", "G21 G90 ; units\nG0 X10 Y10 Z10 ; go\nM2\n"),
    "linuxcnc-nurbs-g5-2": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\nG5.2 X20 Y20 P1 L3\nX30 Y10\nG5.3\nM2\n"),
    "linuxcnc-g33-thread": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\nG33 Z0 K1.5\nM2\n"),
    "linuxcnc-g76-thread": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\nG76 P1.5 Z-10 I-1 J0.1 K1\nM2\n"),
    "linuxcnc-g7-diameter": ("linuxcnc", "G21 G90 G7\nG0 X10 Y10 Z10\nM2\n"),
    "linuxcnc-msg-debug-print": ("linuxcnc", "G21 G90\n(MSG, hello)\n(DEBUG, #1)\n(PRINT, x)\nG0 X10 Y10 Z10\nM2\n"),
    "linuxcnc-m100-user": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\nM100 P1 Q2\nM2\n"),
    "linuxcnc-g10-l20": ("linuxcnc", "G21 G90\nG10 L20 P1 X0 Y0 Z0\nG0 X10 Y10 Z10\nM2\n"),
    "linuxcnc-g92-huge": ("linuxcnc", "G21 G90\nG92 X" + "9" * 60 + "\nG0 X10 Y10 Z10\nM2\n"),
    "linuxcnc-g43-h-nan-expr": ("linuxcnc", "G21 G90\nG43 H[SQRT[-1]]\nG0 X10 Y10 Z10\nM2\n"),
    "linuxcnc-g38-probe": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\nG38.2 Z-10 F50\nM2\n"),
    "linuxcnc-g41-comp": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\nG41 D1\nG1 X20 F100\nM2\n"),
    "linuxcnc-o-return-in-main": ("linuxcnc", "G21 G90\nG0 X10 Y10 Z10\no100 return\nM2\n"),
    "linuxcnc-g52-huge": ("linuxcnc", "G21 G90\nG52 X1e3\nG0 X10 Y10 Z10\nM2\n"),
    "linuxcnc-g64-g61": ("linuxcnc", "G21 G90 G64 P0.01 Q0.01\nG61.1\nG0 X10 Y10 Z10\nM2\n"),
    "fanuc-g68-rotation": ("fanuc", "%\nO1000\nG21 G90\nG68 X0 Y0 R45\nG0 X10 Y10 Z10\nM30\n%\n"),
    "fanuc-g12-1-polar": ("fanuc", "%\nO1000\nG21 G90\nG12.1\nG0 X10 Y10 Z10\nM30\n%\n"),
    "fanuc-g05-1-aicc": ("fanuc", "%\nO1000\nG21 G90\nG05.1 Q1\nG0 X10 Y10 Z10\nM30\n%\n"),
    "fanuc-g54-1-p300": ("fanuc", "%\nO1000\nG21 G90\nG54.1 P300\nG0 X10 Y10 Z10\nM30\n%\n"),
    "fanuc-bprnt": ("fanuc", "%\nO1000\nG21 G90\nPOPEN\nBPRNT[A#1[3]]\nPCLOS\nG0 X10 Y10 Z10\nM30\n%\n"),
    "fanuc-no-percent": ("fanuc", "O1000\nG21 G90\nG0 X10 Y10 Z10\nM30\n"),
    "fanuc-two-o-numbers": ("fanuc", "%\nO1000\nO1000\nG21 G90\nG0 X10 Y10 Z10\nM30\n%\n"),
    "fanuc-eob-semicolons": ("fanuc", "%;\nO1000;\nG21 G90;\nG0 X10 Y10 Z10;\nM30;\n%\n"),
    "haas-g187": ("haas", "%\nO1000\nG21 G90\nG187 P1 E0.01\nG0 X10 Y10 Z10\nM30\n%\n"),
    "haas-g47-engrave": ("haas", "%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nG47 P0 (TEXT) X10 Y10 I0 J1 R0.1 Z-0.1 F10\nM30\n%\n"),
    "haas-g150-pocket": ("haas", "%\nO1000\nG21 G90\nG0 X10 Y10 Z10\nG150 P1 Z-1 Q1 R1 J1 K0.1 D1 F10\nM30\n%\n"),
    "mach3-m98-same-file": ("mach3", "G21 G90\nG0 X10 Y10 Z10\nM98 P2000 L3\nM30\nO2000\nG91 G1 X1 F100\nG90\nM99\n"),
    "mach3-g12-circle": ("mach3", "G21 G90\nG0 X50 Y50 Z10\nG12 I5 F100\nM30\n"),
    "mach3-percent-middle": ("mach3", "G21 G90\nG0 X10 Y10 Z10\n%\nG1 X20 F100\nM30\n"),
    "generic-g28-no-home": ("generic", "G21 G90\nG0 X10 Y10 Z10\nG28\nG1 X20 F100\nM2\n"),
    "generic-g43-no-length": ("generic", "G21 G90\nG43 H1\nG0 X10 Y10 Z10\nM2\n"),
    "generic-g53-g91": ("generic", "G21 G91\nG53 G0 X10 Y10 Z10\nM2\n"),
    "generic-g93-inverse-time": ("generic", "G21 G90 G93\nG0 X10 Y10 Z10\nG1 X20 F0\nM2\n"),
    "generic-canned-no-r": ("generic", "G21 G90\nG0 X10 Y10 Z30\nG81 X20 Y20 Z-5 F100\nG80\nM2\n"),
    "generic-canned-l-huge": ("generic", "G21 G90 G91\nG0 X10 Y10 Z30\nG81 X1 Y0 Z-5 R2 L99999999 F100\nG80\nM2\n"),
}
for nm, (dia, prog) in ODD.items():
    kw = {"timeout": HANG_TIMEOUT_S} if "huge" in nm else {}
    add(f"dialect-{nm}", correct_prog(prog, "--dialect", dia), **kw)


# -- over-long lines per dialect (silent-wrong when an output line passes the limit) -----

LIMITS = {"linuxcnc": 255, "mach3": 255, "fanuc": 128, "haas": 128, "grbl": 127, "generic": 127}
WORD_LIMITS = {"grbl": 79, "generic": 79}


def _words_len(line: str) -> int:
    s = re.sub(r"\([^)]*\)", "", line.split(";")[0])
    return len(re.sub(r"\s", "", s))


def long_line_check(dialect):
    def check(c: Ctx, _err):
        p = c.work / "out.nc"
        if not p.exists():
            return "out.nc missing"
        for i, line in enumerate(p.read_text(errors="replace").splitlines(), 1):
            if len(line) > LIMITS[dialect]:
                return f"output line {i} has {len(line)} chars > {LIMITS[dialect]}"
            if dialect in WORD_LIMITS and _words_len(line) > WORD_LIMITS[dialect]:
                return f"output line {i} has {_words_len(line)} word chars > {WORD_LIMITS[dialect]}"
        return None
    return check


def long_line_prog(dialect):
    lim = LIMITS[dialect]
    if dialect in WORD_LIMITS:
        # 71 word characters (Grbl's limit is 79): grows past it when the coordinates are rewritten
        move = "N12345 G1 G17 G21 G90 G94 X100.1 Y100.1 Z20.1 F500.000000000000 S12000.00000000 M3 M8 T1"
    else:
        move = "G1 X100.1 Y100.1 Z20.1 F500"
        move = move + " (" + "c" * (lim - 3 - len(move) - 3) + ")"
    head = "G21 G90\nG0 X10 Y10 Z10\n"
    if dialect in ("fanuc", "haas"):
        return f"%\nO1000\n{head}{move}\nM30\n%\n"
    return f"{head}{move}\nM2\n"


for dia in LIMITS:
    add(f"longline-{dia}", correct_prog(long_line_prog(dia), "--dialect", dia), check=long_line_check(dia))
add("longline-grbl-75-chars-no-spaces", correct_prog("G21 G90\nG0 X10 Y10 Z10\nN12345G1G17G21G90G94X100.1Y100.1Z20.1F500.000000000000S12000.00000000M3M8T1\nM2\n",
                                           "--dialect", "grbl"), check=long_line_check("grbl"))
add("longline-linuxcnc-input-over-limit", correct_prog("G21 G90\nG0 X10 Y10 Z10 (" + "c" * 300 + ")\nM2\n", "--dialect", "linuxcnc"),
    must_refuse=True)


# -- synchronised I/O on split moves ------------------------------------------------------

def m62_check(c: Ctx, _err):
    p = c.work / "out.nc"
    if not p.exists():
        return "out.nc missing"
    for i, line in enumerate(p.read_text().splitlines(), 1):
        code = re.sub(r"\([^)]*\)", "", line).upper()
        for m in ("M62", "M63", "M64", "M65"):
            if re.search(m + r"(?!\d)", code) and not re.search(r"P\s*[-+]?\d", code):
                return f"line {i}: {m} without its P word: {line.strip()}"
        for m in ("M67", "M68"):
            if re.search(m + r"(?!\d)", code) and not (re.search(r"E\s*\d", code) and re.search(r"Q\s*[-+]?\d", code)):
                return f"line {i}: {m} without its E/Q words: {line.strip()}"
    return None


def m67_first_check(c: Ctx, err):
    bad = m62_check(c, err)
    if bad:
        return bad
    lines = [ln for ln in (c.work / "out.nc").read_text().splitlines() if not ln.lstrip().startswith("(")]
    # the arc's pieces are the lines between the G0 approach and M2; M67 must be on the first
    try:
        start = next(i for i, ln in enumerate(lines) if re.search(r"G0*2(?!\d)|G0*3(?!\d)|G0*1(?!\d)", ln.upper())
                     and "X" in ln.upper() and i > 0)
    except StopIteration:
        return "no arc piece found"
    if "M67" not in lines[start].upper():
        where = next((i for i, ln in enumerate(lines) if "M67" in ln.upper()), None)
        return f"M67 on piece {where - start + 1 if where is not None else '?'} of the split move, not the first"
    return None


SYNC = ("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 F500 M62 P1\nG3 X50 Y100 I-50 J0 M67 E0 Q40\nM2\n")
add("sync-m62-m67-split-issue-repro", correct_prog(SYNC, "--dialect", "linuxcnc", fname="m.ngc"), check=m62_check)
add("sync-m62-split-parametric", correct_prog(SYNC, "--dialect", "linuxcnc", cal="s500_parametric.json"), check=m62_check)
add("sync-m67-on-first-piece", correct_prog("G21 G90 G17\nG0 X50 Y100 Z10\nG2 X150 Y100 I50 J0 F500 M67 E0 Q40\nM2\n",
                                            "--dialect", "linuxcnc"), check=m67_first_check)
add("sync-m64-m65-split", correct_prog("G21 G90\nG0 X10 Y10 Z10\nG1 X300 Y300 Z20 F500 M64 P2\nG1 X10 Y10 M65 P2\nM2\n",
                                       "--dialect", "linuxcnc"), check=m62_check)
add("sync-m62-cycle-expand", correct_prog("G21 G90\nG0 X10 Y10 Z30\nG81 X20 Y20 Z5 R8 F100 M62 P3\nG80\nM2\n",
                                          "--dialect", "linuxcnc", "--cycles", "expand"), check=m62_check)


# -- already corrected ----------------------------------------------------------------------

def twice(force):
    def setup(c: Ctx):
        f = c.write("p.nc", SIMPLE)
        cal = c.cal()
        c.cli("correct", f, "-c", cal, "-o", "once.nc")
        return ["correct", "once.nc", "-c", cal, "-o", "out.nc", *(["--force"] if force else [])]
    return setup


add("corrected-twice", twice(False), must_refuse=True)
add("corrected-twice-force", twice(True), check=out_exists)


def header_spoof(c: Ctx):
    f = c.write("p.nc", "(POSTPROC 9.9 corrected: calibration x sha256 00)\n" + SIMPLE)
    return ["correct", f, "-c", c.cal(), "-o", "out.nc"]


add("corrected-spoofed-header", header_spoof)


def diff_10mm(c: Ctx):
    f = c.write("p.nc", SIMPLE)
    cal = c.cal()
    c.cli("correct", f, "-c", cal, "-o", "once.nc")
    p = c.work / "once.nc"
    if p.exists():
        text = p.read_text()
        text = re.sub(r"X(\d+\.\d+)", lambda m: f"X{float(m.group(1)) + 10:.4f}", text, count=3)
        p.write_text(text)
    return ["diff", f, "once.nc"]


add("diff-10mm-correction", diff_10mm, must_refuse=True, note="a 10 mm 'correction' must warn and exit non-zero")


def diff_junk(c: Ctx):
    a = c.write("p.nc", SIMPLE)
    b = c.write("q.nc", JUNK)
    return ["diff", a, b]


add("diff-binary-corrected", diff_junk, must_refuse=True)
add("diff-empty-both", lambda c: ["diff", c.write("a.nc", ""), c.write("b.nc", "")])


# -- tool tables ---------------------------------------------------------------------------

def tool_table(text):
    def setup(c: Ctx):
        f = c.write("p.nc", "G21 G90\nT1 M6\nG43 H1\nG0 X10 Y10 Z200\nG1 X100 Y100 Z150 F500\nM2\n")
        t = c.write("tool.tbl", text)
        return ["correct", f, "-c", c.cal(), "-o", "out.nc", "--tool-table", t]
    return setup


add("tooltable-ok", tool_table("T1 P1 Z100 D6 ;drill\n"), check=out_exists)
add("tooltable-znan", tool_table("T1 P1 Znan D6 ;drill\n"), must_refuse=True)
add("tooltable-zinf", tool_table("T1 P1 Zinf D6\n"), must_refuse=True)
add("tooltable-z400-digits", tool_table("T1 P1 Z" + "9" * 400 + " D6\n"), must_refuse=True)
add("tooltable-malformed", tool_table("T1 P1 Z\n"), must_refuse=True)
add("tooltable-binary", tool_table(JUNK), must_refuse=True)
add("tooltable-empty", tool_table(""), must_refuse=True)
add("tooltable-duplicate-tool", tool_table("T1 P1 Z100\nT1 P2 Z50\n"))
add("tooltable-huge-tool-number", tool_table("T" + "9" * 40 + " P1 Z100\nT1 P1 Z100\n"))
add("tooltable-missing-file", lambda c: ["correct", c.write("p.nc", SIMPLE), "-c", c.cal(), "-o", "out.nc",
                                         "--tool-table", "none.tbl"], must_refuse=True)


# -- numeric options of every command ----------------------------------------------------

def opt_case(cmd_builder, must_refuse=True, **kw):
    return dict(must_refuse=must_refuse, **kw)


def correct_opts(*opts):
    def setup(c: Ctx):
        f = c.write("p.nc", "G21 G90\nG54\nT1 M6\nG43 H1\nG0 X10 Y10 Z10\nG1 X100 Y100 Z20 F500\nG28\nM2\n")
        base = ["--offset", "G54=X50,Y50,Z150", "--tool-length", "1=100", "--home", "G28=X0,Y0,Z300"]
        extra = list(opts)
        # an option given here replaces the base one of the same name
        for name in ("--offset", "--tool-length", "--home"):
            if name in extra:
                i = base.index(name)
                del base[i:i + 2]
        return ["correct", f, "-c", c.cal(), "-o", "out.nc", *base, *extra]
    return setup


for val in ("nan", "inf", "-inf", "0", "-1", "1e-300", "1e308"):
    add(f"opt-correct-tolerance-{val}", correct_opts("--tolerance", val),
        must_refuse=val not in ("1e308",), timeout=HANG_TIMEOUT_S)
for val in ("nan", "inf", "-1", "1e308"):
    add(f"opt-correct-max-correction-{val}", correct_opts("--max-correction", val), must_refuse=val in ("nan", "-1"))
for val in ("0", "99", "-3"):
    add(f"opt-correct-decimals-{val}", correct_opts("--decimals", val), must_refuse=True)
for spec in ("G54=Xnan,Y50,Z150", "G54=Xinf,Y50,Z150", "G54=X1e400,Y50,Z150", "G54=X" + "9" * 400 + ",Y50,Z150"):
    add(f"opt-correct-offset-{spec[4:8].lower().strip(',')}", correct_opts("--offset", spec), must_refuse=True)
for spec in ("1=nan", "1=inf", "1=-inf", "1=1e400"):
    add(f"opt-correct-tool-length-{spec[2:]}", correct_opts("--tool-length", spec), must_refuse=True)
for spec in ("nan,0,-100", "inf,0,0", "0,0,-1e400"):
    add(f"opt-correct-tool-vector-{spec.split(',')[0].replace('0', 'z')}{'' if spec[0] != '0' else '-e400'}",
        correct_opts("--tool-vector", spec), must_refuse=True)
add("opt-correct-start-znan", correct_opts("--start", "Znan"), must_refuse=True)
add("opt-correct-start-zinf", correct_opts("--start", "Zinf"), must_refuse=True)
add("opt-correct-home-nan", correct_opts("--home", "G28=Xnan,Y0,Z300"), must_refuse=True)
add("opt-correct-context-nan", correct_opts("--context", "temp=nan"), must_refuse=True)
add("opt-correct-jobs-0", correct_opts("-j", "0"), must_refuse=True)
add("opt-correct-jobs-huge", correct_opts("-j", "100000"), must_refuse=True)


def verify_opts(*opts, prog=SIMPLE, points=False):
    def setup(c: Ctx):
        m = c.machine()
        cal = c.cal()
        if points:
            c.sample("s500_control_points.csv")
            return ["verify", "--points", "s500_control_points.csv", "-c", cal, "--machine", m, *opts]
        f = c.write("p.nc", prog)
        return ["verify", f, "-c", cal, "--machine", m, *opts]
    return setup


add("opt-verify-baseline", verify_opts())
for val in ("1e-9", "nan", "inf", "0", "-1"):
    add(f"opt-verify-max-step-{val}", verify_opts("--max-step", val), must_refuse=val != "inf", timeout=HANG_TIMEOUT_S)
add("opt-verify-tolerance-nan", verify_opts("--tolerance", "nan"), must_refuse=True)
add("opt-verify-shots-huge", verify_opts("--shots", "1000000000", points=True), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("opt-verify-seed-huge", verify_opts("--seed", "9" * 40, points=True))
add("opt-verify-fanuc-sample", lambda c: ["verify", c.sample("fanuc_drill.nc"), "-c", c.cal(), "--machine", c.machine(),
                                          "--dialect", "fanuc", "--offset", "G54=X100,Y100,Z100", "--tool-length", "1=100",
                                          "--home", "G28=X0,Y0,Z300", "--cycles", "expand"])


def sim(*opts):
    def setup(c: Ctx):
        return ["simulate", c.machine(), "-o", "sim.csv", *opts]
    return setup


for nm, opts, must in (
        ("grid-1e-3", ("--grid", "0.001"), True), ("grid-nan", ("--grid", "nan"), True), ("grid-0", ("--grid", "0"), True),
        ("grid-negative", ("--grid", "-5"), True), ("random-1e12", ("--random", "1000000000000"), True),
        ("random-negative", ("--random", "-1"), True), ("tables-step-1e-9", ("--tables", "--step", "1e-9"), True),
        ("tables-step-nan", ("--tables", "--step", "nan"), True), ("tables-step-inf", ("--tables", "--step", "inf"), True),
        ("repeats-1e9", ("--static-set", "--repeats", "1000000000"), True),
        ("time-span-nan", ("--static-set", "--time-span", "nan"), True),
        ("temp-profile-nan", ("--static-set", "--temp-profile", "nan"), True),
        ("load-values-inf", ("--static-set", "--load-values", "inf,1"), True),
        ("volume-nan", ("--random", "10", "--volume", "nan,0,0,10,10,10"), True),
        ("volume-1e308", ("--random", "10", "--volume", "0,0,0,1e308,1e308,1e308"), True),
        ("tool-vector-nan", ("--static-set", "--tool-vector", "nan,0,0"), True),
        ("context-nan", ("--static-set", "--context", "temp=nan"), True),
        ("no-mode", (), True)):
    add(f"opt-simulate-{nm}", sim(*opts), must_refuse=must, timeout=HANG_TIMEOUT_S)


def export(*opts, fmt="fanuc"):
    def setup(c: Ctx):
        return ["export", c.cal("s500_parametric.json"), "--format", fmt, "-o", "table.txt" if fmt != "linuxcnc" else "comp",
                *opts]
    return setup


add("opt-export-fanuc-baseline", export("--step", "25", "--reference", "X=0", "--reference", "Y=0", "--reference", "Z=0"))
for val in ("0", "nan", "inf", "1e-300"):
    add(f"opt-export-detection-unit-{val}", export("--step", "25", "--detection-unit", val), must_refuse=True)
for val in ("0", "nan", "1e-9", "inf"):
    add(f"opt-export-step-{val}", export("--step", val, fmt="siemens"), must_refuse=val != "0", timeout=HANG_TIMEOUT_S)
add("opt-export-reference-nan", export("--step", "25", "--reference", "X=nan"), must_refuse=True)
add("opt-export-linuxcnc-step-1e-9", export("--step", "1e-9", fmt="linuxcnc"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("opt-export-static-cal", lambda c: ["export", c.cal(), "--format", "siemens", "-o", "t.spf"], must_refuse=True)


def orders(*opts):
    return lambda c: ["orders", "-c", c.cal("s500_parametric.json"), *opts]


add("opt-orders-k-nan", orders("-k", "nan"), must_refuse=True)
add("opt-orders-point-nan", orders("--point", "nan,0,0"), must_refuse=True)
add("opt-orders-point-1e308", orders("--point", "1e308,0,0"), must_refuse=True)


def check_cmd(*opts):
    return lambda c: ["check", c.sample("s500_static_6points.csv"), "-c", c.cal(), *opts]


add("opt-check-sigma-nan", check_cmd("--sigma", "nan"), must_refuse=True)
add("opt-check-sigma-0", check_cmd("--sigma", "0"), must_refuse=True)
add("opt-check-folds-huge", check_cmd("--folds", "1000000"), must_refuse=True, timeout=HANG_TIMEOUT_S)


def fit_cmd(*opts, sample="s500_static_6points.csv"):
    return lambda c: ["fit", c.sample(sample), "-o", "fitted.json", *opts]


add("opt-fit-max-correction-nan", fit_cmd("--max-correction", "nan"), must_refuse=True)
add("opt-fit-border-blend-nan", fit_cmd("--method", "interval", "--border-blend", "nan"), must_refuse=True)
add("opt-fit-knot-spacing-1e-9", fit_cmd("--method", "parametric", "--knot-spacing", "1e-9"), must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("opt-fit-grid-step-1e-9", fit_cmd("--method", "grid", "--step", "1e-9"), must_refuse=True, timeout=HANG_TIMEOUT_S)
add("opt-fit-intervals-huge", fit_cmd("--method", "interval", "--intervals", "X=1000000;Y=1000000;Z=1000000"), must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("opt-iso230-alpha-nan", lambda c: ["iso230", c.sample("iso230_runs_x.csv"), "--alpha", "nan"], must_refuse=True)


# -- calibrations broken every way (the postproc calibration JSON) -------------------------

def cal_case(mutate, prog=SIMPLE, extra=()):
    def setup(c: Ctx):
        data = c.cal_json("s500_parametric.json" if getattr(mutate, "parametric", False) else "s500_static.json")
        text = mutate(data)
        if not isinstance(text, (str, bytes)):
            text = json.dumps(text)
        cal = c.write("bad.json", text)
        f = c.write("p.nc", prog)
        return ["correct", f, "-c", cal, "-o", "out.nc", *extra]
    return setup


def parametric(fn):
    fn.parametric = True
    return fn


def _set(path, value):
    def mutate(d):
        cur = d
        for k in path[:-1]:
            cur = cur[k]
        if value is _DEL:
            del cur[path[-1]]
        else:
            cur[path[-1]] = value
        return d
    return mutate


_DEL = object()
NAN = float("nan")

CAL_CASES = {
    "not-json": lambda d: "this is not json {",
    "empty": lambda d: "",
    "json-null": lambda d: "null",
    "json-array": lambda d: "[1, 2, 3]",
    "json-string": lambda d: '"postproc calibration"',
    "binary": lambda d: JUNK,
    "utf16": lambda d: json.dumps(d).encode("utf-16"),
    "utf8-bom": lambda d: "\ufeff" + json.dumps(d),
    "format-wrong": _set(["format"], "other"),
    "version-2": _set(["version"], 2),
    "version-string": _set(["version"], "1"),
    "version-5000-digits": lambda d: json.dumps(d).replace('"version": 1', '"version": ' + "9" * 5000),
    "units-inch": _set(["units"], {"length": "in", "angle": "rad"}),
    "units-um": _set(["units"], {"length": "um", "angle": "rad"}),
    "units-deg": _set(["units"], {"length": "mm", "angle": "deg"}),
    "units-missing": _set(["units"], _DEL),
    "method-unknown": _set(["method"], "magic"),
    "method-number": _set(["method"], 7),
    "method-missing": _set(["method"], _DEL),
    "volume-missing": _set(["volume_mm"], _DEL),
    "volume-wrong-shape": _set(["volume_mm"], [[0, 0], [1, 1]]),
    "volume-flat-list": _set(["volume_mm"], [0, 0, 0, 315, 315, 315]),
    "volume-reversed": _set(["volume_mm"], [[315, 315, 315], [0, 0, 0]]),
    "volume-empty": _set(["volume_mm"], [[10, 10, 10], [10, 10, 10]]),
    "volume-1e308": _set(["volume_mm"], [[-1e308, -1e308, -1e308], [1e308, 1e308, 1e308]]),
    "volume-nan": lambda d: json.dumps(_set(["volume_mm"], [[NAN, 0, 0], [315, 315, 315]])(d)),
    "volume-infinity": lambda d: json.dumps(_set(["volume_mm"], [[float("-inf"), 0, 0], [315, 315, 315]])(d)),
    "volume-strings": _set(["volume_mm"], [["a", "b", "c"], ["d", "e", "f"]]),
    "volume-5000-digit-int": lambda d: json.dumps(_set(["volume_mm"], [[0, 0, 0], [315, 315, 315]])(d))
    .replace("315]", "1" + "0" * 5000 + "]", 1),
    "model-missing": _set(["model"], _DEL),
    "model-null": _set(["model"], None),
    "model-g-wrong-shape": _set(["model", "G"], [[1, 0], [0, 1]]),
    "model-g-singular": _set(["model", "G"], [[0, 0, 0], [0, 0, 0], [0, 0, 0]]),
    "model-g-nan": lambda d: json.dumps(_set(["model", "G"], [[NAN, 0, 0], [0, 1, 0], [0, 0, 1]])(d)),
    "model-g-infinity": lambda d: json.dumps(_set(["model", "G"], [[float("inf"), 0, 0], [0, 1, 0], [0, 0, 1]])(d)),
    "model-g-5000-digit-int": lambda d: json.dumps(_set(["model", "G"], [[1, 0, 0], [0, 1, 0], [0, 0, 1]])(d))
    .replace("[1, 0, 0]", "[" + "1" * 5000 + ", 0, 0]", 1),
    "model-g-1e308": _set(["model", "G"], [[1e308, 0, 0], [0, 1e308, 0], [0, 0, 1e308]]),
    "model-g-strings": _set(["model", "G"], [["1", "0", "0"], ["0", "1", "0"], ["0", "0", "1"]]),
    "model-r-missing": _set(["model", "r_O1_mm"], _DEL),
    "deeply-nested-json": lambda d: '{"format": "postproc calibration", "version": 1, "x": ' + "[" * 100_000 + "]" * 100_000 + "}",
    "deeply-nested-model": lambda d: json.dumps(d).replace('"model": {', '"model": {"deep": ' + "[" * 50_000 + "]" * 50_000 + ", ", 1),
    "effects-unknown": _set(["effects"], [{"name": "warp:Q", "params": {}}]),
    "effects-not-list": _set(["effects"], "backlash:X"),
    "effects-params-nan": lambda d: json.dumps(_set(["effects"], [{"name": "backlash:X", "params": {"b_mm": NAN}}])(d)),
    "effects-params-missing": _set(["effects"], [{"name": "backlash:X"}]),
    "param-grid-step-1e-9": parametric(lambda d: (_set(["model", "solver"], "astatic")(d),
                                                  _set(["model", "astatic", "grid_step_mm"], 1e-9)(d))[1]),
    "param-astatic-max-iter-huge": parametric(lambda d: (_set(["model", "solver"], "astatic")(d),
                                                         _set(["model", "astatic", "max_iter"], 10 ** 12)(d))[1]),
    "param-astatic-gain-nan": parametric(lambda d: json.dumps((_set(["model", "solver"], "astatic")(d),
                                                               _set(["model", "astatic", "gain"], NAN)(d))[1])),
    "param-order-unknown": parametric(_set(["model", "order"], "fourth")),
    "param-solver-unknown": parametric(_set(["model", "solver"], "magic")),
    "param-interpolation-unknown": parametric(_set(["model", "interpolation"], "cubic-magic")),
    "param-table-axis-missing": parametric(lambda d: (d["model"]["tables"].pop("X"), d)[1]),
    "param-table-positions-unsorted": parametric(lambda d: (d["model"]["tables"]["X"]["position_mm"].reverse(), d)[1]),
    "param-table-positions-duplicate": parametric(lambda d: (d["model"]["tables"]["X"].__setitem__(
        "position_mm", [0.0] * len(d["model"]["tables"]["X"]["position_mm"])), d)[1]),
    "param-table-length-mismatch": parametric(lambda d: (d["model"]["tables"]["X"]["position_mm"].pop(), d)[1]),
    "param-table-nan": parametric(lambda d: json.dumps((d["model"]["tables"]["X"]["position_mm"].__setitem__(3, NAN), d)[1])),
    "param-table-empty": parametric(lambda d: ([v.clear() for v in d["model"]["tables"]["X"].values() if isinstance(v, list)], d)[1]),
    "param-squareness-nan": parametric(lambda d: json.dumps(_set(["model", "squareness_rad", "EC0Y"], NAN)(d))),
    "param-squareness-huge": parametric(_set(["model", "squareness_rad", "EC0Y"], 1e6)),
    "param-volume-1e308": parametric(_set(["volume_mm"], [[-1e308, -1e308, -1e308], [1e308, 1e308, 1e308]])),
}
for nm, mut in CAL_CASES.items():
    must = nm not in ("utf8-bom", "param-astatic-max-iter-huge")
    slow = any(k in nm for k in ("1e-9", "huge", "deep", "1e308", "5000"))
    add(f"cal-json-{nm}", cal_case(mut), must_refuse=must, **({"timeout": HANG_TIMEOUT_S} if slow else {}))


def cal_special(path_fn, must=True):
    def setup(c: Ctx):
        return ["correct", c.write("p.nc", SIMPLE), "-c", path_fn(c), "-o", "out.nc"]
    return setup


add("cal-path-missing", cal_special(lambda c: "none.json"), must_refuse=True)
add("cal-path-directory", cal_special(lambda c: (c.work / "d").mkdir() or "d"), must_refuse=True)
add("cal-path-dev-null", cal_special(lambda c: "/dev/null"), must_refuse=True)
add("cal-path-measurement-csv", cal_special(lambda c: c.sample("s500_static_6points.csv")), must_refuse=True)


# grid and interval engines (fitted here from the sample, then broken)

def fitted_cal(method, mutate, fit_args=()):
    def setup(c: Ctx):
        # a lattice of tracker points from the virtual machine, fitted with the method
        c.cli("simulate", c.machine(), "--grid", "105", "--no-noise", "-o", "lattice.csv")
        c.cli("fit", "lattice.csv", "--method", method, "-o", "good.json", *fit_args)
        p = c.work / "good.json"
        if p.exists():
            d = json.loads(p.read_text())
            t = mutate(d)
            c.write("bad.json", t if isinstance(t, str) else json.dumps(t))
        f = c.write("p.nc", "G21 G90\nG0 X10 Y10 Z10\nG1 X100 Y100 Z20 F500\nM2\n")
        return ["correct", f, "-c", "bad.json", "-o", "out.nc", "--extrapolate", "clamp"]
    return setup


add("cal-grid-step-zero", fitted_cal("grid", _set(["model", "step_mm"], [0, 0, 0])), must_refuse=True)
add("cal-grid-step-1e-9", fitted_cal("grid", _set(["model", "step_mm"], [1e-9, 1e-9, 1e-9])), must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("cal-grid-shape-huge", fitted_cal("grid", _set(["model", "shape"], [100000, 100000, 100000])), must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("cal-grid-q1-nan", fitted_cal("grid", lambda d: json.dumps(_set(["model", "origin_q_mm"], [NAN, 0, 0])(d))),
    must_refuse=True)
add("cal-grid-q-wrong-shape", fitted_cal("grid", _set(["model", "Q1"], [[1, 2], [3]])), must_refuse=True)
add("cal-interval-edges-unsorted", fitted_cal("interval", lambda d: (d["model"]["edges_mm"][0].reverse(), d)[1]),
    must_refuse=True)
add("cal-interval-edges-nan", fitted_cal("interval", lambda d: json.dumps(
    (d["model"]["edges_mm"][0].__setitem__(0, NAN), d)[1])), must_refuse=True)
add("cal-interval-static-missing", fitted_cal("interval", lambda d: (d["model"].pop("static"), d)[1]), must_refuse=True)
add("cal-interval-blend-nan", fitted_cal("interval", lambda d: json.dumps(_set(["model", "border_blend_mm"], NAN)(d))),
    must_refuse=True)


# -- machine JSON (simulate/verify) ----------------------------------------------------------

def machine_case(mutate, tables_text=None):
    def setup(c: Ctx):
        c.machine()
        d = json.loads((c.work / "s500.machine.json").read_text())
        t = mutate(d)
        c.write("bad.machine.json", t if isinstance(t, str) else json.dumps(t))
        if tables_text is not None:
            c.write("s500_tables.csv", tables_text)
        return ["simulate", "bad.machine.json", "--static-set", "-o", "sim.csv"]
    return setup


MACHINE = {
    "tables-missing-file": _set(["tables"], "nowhere.csv"),
    "tables-escape-path": _set(["tables"], "/etc/passwd"),
    "volume-1e308": _set(["volume_mm"], [[0, 0, 0], [1e308, 1e308, 1e308]]),
    "volume-nan": lambda d: json.dumps(_set(["volume_mm"], [[NAN, 0, 0], [315, 315, 315]])(d)),
    "rotation-unknown": _set(["rotation"], "quaternion"),
    "noise-negative": _set(["noise", "tracker_mm"], -1),
    "noise-nan": lambda d: json.dumps(_set(["noise", "tracker_mm"], NAN)(d)),
    "deeply-nested": lambda d: '{"format": "postproc machine", "version": 1, "x": ' + "[" * 100_000 + "]" * 100_000 + "}",
    "units-inch": _set(["units"], {"length": "in", "angle": "rad"}),
}
for nm, mut in MACHINE.items():
    add(f"machine-{nm}", machine_case(mut), must_refuse=True)
add("machine-tables-nan", machine_case(lambda d: d, "# postproc axis error tables v1\n# units: length=mm angle=rad\n"
                                       "axis,position,EX,EY,EZ,EA,EB,EC\nX,0,nan,0,0,0,0,0\nX,315,0,0,0,0,0,0\n"
                                       "Y,0,0,0,0,0,0,0\nY,315,0,0,0,0,0,0\nZ,0,0,0,0,0,0,0\nZ,315,0,0,0,0,0,0\n"),
    must_refuse=True)


# -- CSV formats (fit, check, iso230, predict chain) ----------------------------------------

MEAS_HEAD = "# postproc measurements v1\n# units: length=mm\nX,Y,Z,mx,my,mz\n"


def meas_rows(n=30, bad=None):
    rows = []
    r = random.Random(5)
    for _ in range(n):
        x, y, z = (r.uniform(0, 300) for _ in range(3))
        rows.append(f"{x:.3f},{y:.3f},{z:.3f},{x + 0.01:.4f},{y - 0.02:.4f},{z + 0.005:.4f}")
    if bad is not None:
        rows[3] = bad
    return "\n".join(rows) + "\n"


def fit_file(text, name="m.csv", *opts):
    return lambda c: ["fit", c.write(name, text), "-o", "fitted.json", *opts]


CSV = {
    "meas-nan": MEAS_HEAD + meas_rows(bad="10,10,10,nan,10,10"),
    "meas-inf": MEAS_HEAD + meas_rows(bad="10,10,10,inf,10,10"),
    "meas-5000-digits": MEAS_HEAD + meas_rows(bad="10,10,10," + "9" * 5000 + ",10,10"),
    "meas-1e308": MEAS_HEAD + meas_rows(bad="1e308,10,10,1e308,10,10"),
    "meas-header-only": MEAS_HEAD,
    "meas-no-header": meas_rows(),
    "meas-units-inch": MEAS_HEAD.replace("length=mm", "length=inch") + meas_rows(),
    "meas-short-row": MEAS_HEAD + meas_rows(bad="10,10"),
    "meas-long-row": MEAS_HEAD + meas_rows(bad="10,10,10,10,10,10,10,10,10"),
    "meas-duplicate-column": "# postproc measurements v1\n# units: length=mm\nX,X,Y,Z,mx,my,mz\n" + "1,1,2,3,1,2,3\n" * 10,
    "meas-all-same-point": MEAS_HEAD + "10,10,10,10.01,10,10\n" * 30,
    "meas-one-row": MEAS_HEAD + "10,10,10,10.01,10,10\n",
    "meas-binary": JUNK,
    "meas-text-values": MEAS_HEAD + meas_rows(bad="a,b,c,d,e,f"),
    "meas-dir-2": "# postproc measurements v1\n# units: length=mm\nX,Y,Z,mx,my,mz,dirx,diry,dirz\n"
                  + "".join(f"{i},{i},{i},{i},{i},{i},2,1,1\n" for i in range(10, 40)),
    "tables-nan": "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                  "X,0,nan,0,0,0,0,0\nX,100,0,0,0,0,0,0\nY,0,0,0,0,0,0,0\nY,100,0,0,0,0,0,0\nZ,0,0,0,0,0,0,0\nZ,100,0,0,0,0,0,0\n",
    "tables-unsorted": "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                       "X,100,0,0,0,0,0,0\nX,0,0,0,0,0,0,0\nX,100,1,0,0,0,0,0\n",
    "tables-single-position": "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                              "X,0,0,0,0,0,0,0\n",
    "tables-axis-q": "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                     "Q,0,0,0,0,0,0,0\nQ,100,0,0,0,0,0,0\n",
    "tables-angle-deg": "# postproc axis error tables v1\n# units: length=mm angle=deg\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                        "X,0,0,0,0,0,0,0\nX,100,0,0,0,0,0,0\n",
    "tables-spacing-1e-9": "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                           "X,0,0,0,0,0,0,0\nX,0.000000001,0,0,0,0,0,0\nX,300,0,0,0,0,0,0\n",
    "tables-position-1e308": "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                             "X,0,0,0,0,0,0,0\nX,1e308,0,0,0,0,0,0\n",
    "squareness-nan": "# postproc squareness v1\n# units: angle=rad\nname,value\nEC0Y,nan\n",
    "squareness-unknown-name": "# postproc squareness v1\n# units: angle=rad\nname,value\nEQ0Q,1e-4\n",
    "runs-nan": "# postproc iso230 runs v1\n# units: length=mm error=um\naxis,target,run,direction,deviation\n"
                + "".join(f"X,{t},{r},{d},{'nan' if (t, r) == (0, 1) else 1.0}\n" for t in (0, 100, 200) for r in (1, 2, 3)
                          for d in "+-"),
    "runs-direction-x": "# postproc iso230 runs v1\n# units: length=mm error=um\naxis,target,run,direction,deviation\n"
                        + "".join(f"X,{t},{r},x,1.0\n" for t in (0, 100, 200) for r in (1, 2, 3)),
    "runs-one-target": "# postproc iso230 runs v1\n# units: length=mm error=um\naxis,target,run,direction,deviation\n"
                       "X,0,1,+,1.0\nX,0,1,-,1.0\n",
    "runs-huge-run-number": "# postproc iso230 runs v1\n# units: length=mm error=um\naxis,target,run,direction,deviation\n"
                            + "".join(f"X,{t},{'9' * 400 if r == 1 else r},{d},1.0\n" for t in (0, 100, 200) for r in (1, 2)
                                      for d in "+-"),
    "isg-junk": "// TF5280\nEXX EXY EXZ\n1 2\nnan nan nan\n",
    "unknown-kind": "a,b,c\n1,2,3\n",
}
for nm, text in CSV.items():
    must = not nm.startswith("tables-unsorted")
    if nm.startswith("squareness"):
        def sq(c, text=text):
            c.write("t.csv", "# postproc axis error tables v1\n# units: length=mm angle=rad\naxis,position,EX,EY,EZ,EA,EB,EC\n"
                    + "".join(f"{a},{p},0,0,0,0,0,0\n" for a in "XYZ" for p in (0, 100, 200, 300)))
            return ["fit", "t.csv", "--squareness", c.write("sq.csv", text), "-o", "fitted.json"]
        add(f"csv-{nm}", sq, must_refuse=must)
    elif nm.startswith("runs"):
        add(f"csv-{nm}", lambda c, text=text: ["iso230", c.write("r.csv", text)], must_refuse=must)
    else:
        add(f"csv-{nm}", fit_file(text), must_refuse=must, timeout=HANG_TIMEOUT_S)
add("csv-runs-nan-fit", lambda c: ["fit", c.write("r.csv", CSV["runs-nan"]), "-o", "fitted.json"], must_refuse=True)
add("csv-check-meas-nan", lambda c: ["check", c.write("m.csv", CSV["meas-nan"]), "-c", c.cal()], must_refuse=True)
add("csv-verify-points-nan", lambda c: ["verify", "--points", c.write("m.csv", "X,Y,Z\n10,10,10\nnan,10,10\n"), "-c", c.cal(),
                                        "--machine", c.machine()], must_refuse=True)


# -- inputs, outputs and the file system -------------------------------------------------------

def io_case(out, *extra, inp=SIMPLE):
    def setup(c: Ctx):
        f = c.write("p.nc", inp)
        if callable(out):
            o = out(c)
        else:
            o = out
        return ["correct", f, "-c", c.cal(), "-o", o, *extra]
    return setup


def ro_dir(c: Ctx):
    d = c.work / "ro"
    d.mkdir()
    os.chmod(d, 0o555)
    return "ro/out.nc"


add("io-output-dev-full-enospc", io_case("/dev/full"), must_refuse=True)
add("io-output-dev-full-large", io_case("/dev/full", inp="G21 G90\nG0 X10 Y10 Z10\nG1 F500\n"
                                        + "".join(f"X{10 + i % 200} Y{10 + (i * 7) % 200}\n" for i in range(3000)) + "M2\n"),
    must_refuse=True)
add("io-output-dev-null", io_case("/dev/null"))
add("io-output-stdout", io_case("-"))
add("io-output-missing-dir", io_case("nodir/sub/out.nc"), must_refuse=True)
add("io-output-readonly-dir", io_case(ro_dir), note="root ignores 0555; ok expected when run as root")
add("io-output-sysfs", io_case("/sys/postproc-hostile-out.nc"), must_refuse=True)
add("io-output-is-directory", io_case(lambda c: (c.work / "od").mkdir() or "od"), must_refuse=True)
add("io-output-same-as-input", io_case("p.nc"))
add("io-output-dir-missing", lambda c: ["correct", c.write("p.nc", SIMPLE), "-c", c.cal(), "--output-dir", "nowhere/x"])
add("io-input-missing", lambda c: ["correct", "none.nc", "-c", c.cal(), "-o", "out.nc"], must_refuse=True)
add("io-input-directory-empty", lambda c: ["correct", (c.work / "empty").mkdir() or "empty", "-c", c.cal(),
                                           "--output-dir", "o"], must_refuse=True)
add("io-input-dev-zero", lambda c: ["correct", "/dev/zero", "-c", c.cal(), "-o", "out.nc"], must_refuse=True,
    timeout=HANG_TIMEOUT_S)
add("io-input-dev-null", lambda c: ["correct", "/dev/null", "-c", c.cal(), "-o", "out.nc"], must_refuse=True)
add("io-stdin-program", lambda c: ["correct", "-", "-c", c.cal(), "-o", "out.nc"], stdin=lambda c: SIMPLE.encode(),
    check=out_exists)
add("io-stdin-empty", lambda c: ["correct", "-", "-c", c.cal(), "-o", "out.nc"], stdin=lambda c: b"", must_refuse=True)
add("io-stdin-binary", lambda c: ["correct", "-", "-c", c.cal(), "-o", "out.nc"], stdin=lambda c: JUNK, must_refuse=True)
add("io-stdin-to-stdout", lambda c: ["correct", "-", "-c", c.cal(), "-o", "-"], stdin=lambda c: SIMPLE.encode())
add("io-stdin-dev-zero", lambda c: ["correct", "-", "-c", c.cal(), "-o", "out.nc"], stdin_path="/dev/zero", must_refuse=True,
    timeout=HANG_TIMEOUT_S)


# -- signals mid-run --------------------------------------------------------------------------

# a program that runs a while and stays within the output bound (800,000 lines of 1,000,450)
LONG = ("G21 G90\nG0 X10 Y10 Z10\n#1=0\no100 while [#1 LT 400000]\nG1 X20 Y20 F100\nG1 X10 Y10\n#1=[#1+1]\n"
        "o100 endwhile\nM2\n")
for sig in (signal.SIGTERM, signal.SIGINT, signal.SIGHUP):
    nm = sig.name[3:].lower()
    add(f"signal-{nm}-file", correct_prog(LONG, "--dialect", "linuxcnc"), sig=sig, timeout=HANG_TIMEOUT_S)
    add(f"signal-{nm}-stdin", lambda c: ["correct", "-", "-c", c.cal(), "-o", "out.nc", "--dialect", "linuxcnc"],
        stdin=lambda c: LONG.encode(), sig=sig, timeout=HANG_TIMEOUT_S)
add("signal-term-stdout", lambda c: ["correct", c.write("p.nc", LONG), "-c", c.cal(), "-o", "-", "--dialect", "linuxcnc"],
    sig=signal.SIGTERM, timeout=HANG_TIMEOUT_S)


# ---------------------------------------------------------------------------------- running

def _limits():
    resource.setrlimit(resource.RLIMIT_AS, (AS_LIMIT, AS_LIMIT))
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))


def _snapshot(d: Path) -> set:
    return {str(p.relative_to(d)) for p in d.rglob("*")} if d.exists() else set()


def _kill_group(proc):
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


PLACE_COL = re.compile(r"(^|\s)[^\s:]+:\d+:\d+:")
PLACE_LINE = re.compile(r"(^|\s)[^\s:]+:\d+:(?!\d)")


def run_case(cs: Case, root: Path) -> dict:
    base = Path(tempfile.mkdtemp(prefix="hostile-"))
    work, tmp = base / "work", base / "tmp"
    work.mkdir()
    tmp.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith("POSTPROC")}
    env.update(PYTHONPATH=str(root), TMPDIR=str(tmp), PYTHONDONTWRITEBYTECODE="1", PYTHONWARNINGS="default",
               LC_ALL="C.UTF-8")
    ctx = Ctx(work, root, env)
    res = {"case": cs.name, "outcome": "", "exit": None, "stderr": "", "seconds": 0.0, "detail": cs.note}
    try:
        try:
            argv = cs.setup(ctx)
        except Exception as exc:  # noqa: BLE001 - a setup that cannot run is reported, not fatal
            res.update(outcome="setup-failed", stderr=f"{type(exc).__name__}: {exc}")
            return res
        if ctx.pre_failed:
            res.update(outcome="setup-failed", stderr=ctx.pre_failed[0][:160])
            return res
        tmp_before = _snapshot(tmp)
        work_before = _snapshot(work)
        stdin_data = cs.stdin(ctx) if cs.stdin else None
        stdin_fh = open(cs.stdin_path, "rb") if cs.stdin_path else None
        t0 = time.monotonic()
        proc = subprocess.Popen([sys.executable, "-m", "postproc", *argv], cwd=work, env=env,
                                stdin=stdin_fh or (subprocess.PIPE if stdin_data is not None else subprocess.DEVNULL),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_limits,
                                start_new_session=True)
        timed_out = False
        sent = None
        try:
            if cs.signal is not None:
                if stdin_data is not None:
                    proc.stdin.write(stdin_data)
                    proc.stdin.close()
                    proc.stdin = None
                    stdin_data = None
                # wait until the run has started working (a temporary file appears), then signal it
                deadline = time.monotonic() + 15
                while time.monotonic() < deadline and proc.poll() is None:
                    if _snapshot(tmp) - tmp_before or _snapshot(work) - work_before:
                        break
                    time.sleep(0.2)
                time.sleep(1.5)
                if proc.poll() is None:
                    proc.send_signal(cs.signal)
                    sent = cs.signal
            out, err = proc.communicate(input=stdin_data, timeout=cs.timeout)
        except subprocess.TimeoutExpired:
            timed_out = True
            _kill_group(proc)
            out, err = proc.communicate()
        finally:
            if stdin_fh:
                stdin_fh.close()
        res["seconds"] = round(time.monotonic() - t0, 2)
        rc = proc.returncode
        res["exit"] = rc
        err_text = err.decode("utf-8", errors="replace")
        lines = [ln for ln in err_text.splitlines() if ln.strip()]
        res["stderr"] = lines[0].strip()[:160] if lines else ""
        time.sleep(0.1)
        new_tmp = sorted(_snapshot(tmp) - tmp_before)
        new_work = sorted(_snapshot(work) - work_before)
        res["outcome"], why = classify(cs, ctx, rc, err_text, timed_out, sent, new_tmp, new_work)
        if why:
            res["detail"] = (res["detail"] + "; " if res["detail"] else "") + why
        if ctx.pre_failed:
            res["detail"] = (res["detail"] + "; " if res["detail"] else "") + ctx.pre_failed[0][:200]
        return res
    finally:
        for d in base.rglob("*"):
            try:
                if d.is_dir() and not d.is_symlink():
                    os.chmod(d, 0o755)
            except OSError:
                pass
        shutil.rmtree(base, ignore_errors=True)


def refusal_codes(root: Path) -> set:
    """The documented refusal exit codes of the checkout: its EXIT_* constants in
    postproc/errors.py other than 0 (done) and 1 (internal error); 2-6 when none are found."""
    try:
        text = (root / "postproc" / "errors.py").read_text()
    except OSError:
        text = ""
    codes = {int(v) for v in re.findall(r"^EXIT_\w+\s*=\s*(\d+)", text, re.M)} - {0, 1}
    return codes or {2, 3, 4, 5, 6}


def classify(cs, ctx, rc, err, timed_out, sent, new_tmp, new_work):  # noqa: C901 - one rule per outcome
    if timed_out:
        return "hang", f"no exit within {cs.timeout} s"
    if "MemoryError" in err or rc in (-signal.SIGKILL, -signal.SIGSEGV, -signal.SIGABRT, 137, 139):
        return "memory", f"exit {rc}" + (" MemoryError" if "MemoryError" in err else "")
    temp_like = [p for p in new_work if p.endswith(".tmp") or Path(p).name.startswith(".")
                 or "postproc-" in p]
    if sent is not None:
        if rc not in (128 + sent, -sent):
            if new_tmp or temp_like:
                return "bad-exit", f"exit {rc} after {signal.Signals(sent).name}; also left {(new_tmp + temp_like)[:3]}"
            return "bad-exit", f"exit {rc} after {signal.Signals(sent).name}, not {128 + sent}"
    if new_tmp:
        return "leftover", f"left in TMPDIR: {new_tmp[:3]}"
    if temp_like:
        return "leftover", f"left beside the output: {temp_like[:3]}"
    if sent is not None:
        wrote = [p for p in new_work if p == "out.nc"]
        if wrote:
            return "leftover", "an interrupted run left out.nc"
        return "ok", f"interrupted by {signal.Signals(sent).name}, exit {rc}, clean"
    if rc == 0 and cs.signal is not None:
        return "ok", "finished before the signal"
    if "Traceback (most recent call last)" in err or "internal error" in err.lower() or rc == 1:
        return "internal", ""
    if re.search(r"\b\w*Warning\b", err) and re.search(r"RuntimeWarning|DeprecationWarning|UserWarning|warnings\.warn|"
                                                       r"Warning:", err):
        return "warning-leak", ""
    if rc == 0:
        if cs.must_refuse:
            return "silent-wrong", "exit 0 where a refusal is required"
        if cs.check:
            why = cs.check(ctx, err)
            if why:
                return "silent-wrong", why
        return "ok", ""
    if rc in refusal_codes(ctx.root):
        if rc != 2 and [p for p in new_work if p in ("out.nc", "fitted.json", "sim.csv", "table.txt", "t.spf")]:
            return "leftover", f"refused (exit {rc}) but wrote {new_work[:3]}"
        first = next((ln for ln in err.splitlines() if ln.strip()), "")
        if PLACE_COL.search(first):
            return "refused", ""
        if PLACE_LINE.search(first):
            return "refused-no-col", ""
        if first:
            return "refused", "no place in the message"
        return "refused", "no message"
    return "bad-exit", f"undocumented exit {rc}"


# ---------------------------------------------------------------------------------- reports

def table(results: list[dict]) -> str:
    w = max(len(r["case"]) for r in results)
    lines = [f"{'case':<{w}}  {'outcome':<14} {'exit':>5}  first stderr line", "-" * (w + 80)]
    for r in results:
        ex = "" if r["exit"] is None else str(r["exit"])
        lines.append(f"{r['case']:<{w}}  {r['outcome']:<14} {ex:>5}  {r['stderr'][:100]}")
    lines.append("")
    lines.append(summary(results))
    return "\n".join(lines)


def summary(results: list[dict]) -> str:
    counts = {o: 0 for o in OUTCOMES}
    for r in results:
        counts[r["outcome"]] = counts.get(r["outcome"], 0) + 1
    parts = [f"{o} {n}" for o, n in counts.items() if n]
    return f"{len(results)} cases: " + ", ".join(parts)


def compare(old_path: str, new_path: str) -> str:
    old = {r["case"]: r for r in json.loads(Path(old_path).read_text())["results"]}
    new = {r["case"]: r for r in json.loads(Path(new_path).read_text())["results"]}
    names = list(old) + [n for n in new if n not in old]
    w = max(len(n) for n in names)
    lines = [f"{'case':<{w}}  {'before':<14} -> {'after':<14} {'exit':>11}  after: first stderr line", "-" * (w + 100)]
    changed = 0
    for n in names:
        a, b = old.get(n), new.get(n)
        ao = a["outcome"] if a else "-"
        bo = b["outcome"] if b else "-"
        ex = f"{a['exit'] if a else '-'}->{b['exit'] if b else '-'}"
        mark = "" if ao == bo else " *"
        changed += ao != bo
        lines.append(f"{n:<{w}}  {ao:<14} -> {bo:<14} {ex:>11}  {(b or {}).get('stderr', '')[:90]}{mark}")
    lines.append("")
    lines.append("before: " + summary(list(old.values())))
    lines.append("after:  " + summary(list(new.values())))
    lines.append(f"{changed} cases changed outcome (*)")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", help="checkout whose CLI to run (PYTHONPATH)")
    ap.add_argument("--json", metavar="OUT", help="write the results as JSON")
    ap.add_argument("--compare", nargs=2, metavar=("OLD.json", "NEW.json"), help="print the before -> after table")
    ap.add_argument("-k", metavar="TEXT", help="run only the cases whose name contains TEXT")
    ap.add_argument("--list", action="store_true", help="list the cases")
    args = ap.parse_args(argv)
    if args.compare:
        print(compare(*args.compare))
        return 0
    cases = [c for c in CASES if not args.k or args.k in c.name]
    names = [c.name for c in CASES]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        ap.error(f"duplicate case names: {sorted(dup)}")
    if args.list:
        for c in cases:
            print(c.name)
        print(f"{len(cases)} cases")
        return 0
    if not args.root:
        ap.error("--root is required (or --compare / --list)")
    root = Path(args.root).resolve()
    results = []
    t0 = time.monotonic()
    for i, cs in enumerate(cases, 1):
        r = run_case(cs, root)
        results.append(r)
        print(f"[{i}/{len(cases)}] {r['case']}: {r['outcome']} (exit {r['exit']}, {r['seconds']} s)",
              file=sys.stderr, flush=True)
    print(table(results))
    print(f"total {time.monotonic() - t0:.0f} s against {root}")
    if args.json:
        Path(args.json).write_text(json.dumps({"root": str(root), "cases": len(results), "summary": summary(results),
                                               "results": results}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
