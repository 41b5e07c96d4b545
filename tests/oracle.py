"""LinuxCNC's own interpreter as a test oracle.

``rs274`` (Debian package ``linuxcnc-uspace``) is LinuxCNC's standalone interpreter:
``rs274 -t TOOLS.tbl -g IN.ngc OUT.txt`` writes the canonical machining calls
(``STRAIGHT_TRAVERSE``, ``STRAIGHT_FEED``, ``ARC_FEED``, ...) that the program
produces. It exits non-zero and prints the error and the offending line on stderr
when it refuses a program. Tests use it through :func:`run_rs274` and skip when it
is absent (:data:`requires_rs274`).

Canonical positions are printed with 4 decimals; ``ARC_FEED`` prints its end point
and centre in the plane's own axis order (XY: X Y; XZ: Z X; YZ: Y Z), then the
turn count (sign = direction, ``1`` counter-clockwise), then the end point on the
plane's normal axis. :class:`Motion` stores both the raw fields and X/Y/Z.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

RS274 = shutil.which("rs274")
requires_rs274 = pytest.mark.skipif(
    RS274 is None, reason="LinuxCNC's rs274 is not installed (apt-get install linuxcnc-uspace)"
)
# rs274 writes positions with 4 decimals: a difference below this is the same position.
RS274_RESOLUTION = 1e-4
# Tool table used when a test gives none: tools 1..99, zero length and diameter, so that
# T/M6/G43 in real programs are accepted and change nothing.
DEFAULT_TOOLS = "".join(f"T{n} P{n} Z0 D0\n" for n in range(1, 100))
# Wall-clock cap for one rs274 run (s): programs in the tests run in milliseconds.
RS274_TIMEOUT_S = 60

_CALL = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z_0-9]+)\((.*)\)\s*$")
_PLANE_AXES = {
    # plane: (first, second, normal) axis indices into (x, y, z)
    "CANON_PLANE_XY": (0, 1, 2),
    "CANON_PLANE_XZ": (2, 0, 1),
    "CANON_PLANE_YZ": (1, 2, 0),
}


@dataclass(frozen=True, slots=True)
class Motion:
    """One canonical motion."""

    kind: str  # STRAIGHT_TRAVERSE, STRAIGHT_FEED, ARC_FEED
    end: tuple[float, ...]  # x, y, z, then the rotary/extra axes rs274 prints
    centre: tuple[float, float, float] | None = None  # ARC_FEED: centre (normal axis: end's)
    turn: int = 0  # ARC_FEED: signed turn count (positive = counter-clockwise)
    plane: str = ""  # ARC_FEED: XY, XZ or YZ

    def close_to(self, other: Motion, tol: float = RS274_RESOLUTION * 1.5) -> bool:
        if self.kind != other.kind or self.turn != other.turn or self.plane != other.plane:
            return False
        if len(self.end) != len(other.end):
            return False
        if any(abs(a - b) > tol for a, b in zip(self.end, other.end, strict=True)):
            return False
        if (self.centre is None) != (other.centre is None):
            return False
        if self.centre is not None:
            return all(abs(a - b) <= tol for a, b in zip(self.centre, other.centre, strict=True))
        return True


@dataclass(slots=True)
class Rs274Result:
    ok: bool  # rs274 ran the program to its end without an error
    error: str  # rs274's error text (stderr without its progress line), "" when ok
    motions: list[Motion] = field(default_factory=list)
    calls: list[str] = field(default_factory=list)  # every canonical call, "NAME(args)"


def parse_canon(text: str) -> tuple[list[Motion], list[str]]:
    """Motions and calls from rs274's canonical output."""
    motions: list[Motion] = []
    calls: list[str] = []
    plane = "CANON_PLANE_XY"
    for line in text.splitlines():
        m = _CALL.match(line)
        if not m:
            continue
        name, args = m.group(1), m.group(2)
        calls.append(f"{name}({args})")
        if name == "SELECT_PLANE":
            plane = args.strip()
            continue
        if name in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED"):
            vals = tuple(float(a) for a in args.split(","))
            motions.append(Motion(name, vals))
        elif name == "ARC_FEED":
            parts = [a.strip() for a in args.split(",")]
            first_end, second_end, first_c, second_c = (float(p) for p in parts[:4])
            turn = int(parts[4])
            axis_end = float(parts[5])
            rest = tuple(float(p) for p in parts[6:])
            i1, i2, inorm = _PLANE_AXES[plane]
            end = [0.0, 0.0, 0.0]
            end[i1], end[i2], end[inorm] = first_end, second_end, axis_end
            centre = [0.0, 0.0, 0.0]
            centre[i1], centre[i2], centre[inorm] = first_c, second_c, axis_end
            motions.append(Motion(name, tuple(end) + rest, tuple(centre), turn,
                                  plane.removeprefix("CANON_PLANE_")))
    return motions, calls


def _write_var_file(path: Path, params: dict[int, float]) -> None:
    lines = [f"{k}\t{v:.6f}\n" for k, v in sorted(params.items())]
    path.write_text("".join(lines))


def run_rs274(text: str, tools: str | None = None, params: dict[int, float] | None = None,
              *, files: dict[str, str] | None = None, timeout: float = RS274_TIMEOUT_S) -> Rs274Result:
    """Run ``text`` through rs274 and parse what it did.

    ``tools`` is the text of a LinuxCNC tool table (``T1 P1 D6 Z10``; default
    :data:`DEFAULT_TOOLS`), ``params`` the
    numbered parameters to start with (a .var file), ``files`` extra files (name ->
    text) put in a directory that is the interpreter's SUBROUTINE_PATH, ``timeout`` the
    wall-clock cap of one run (s).
    """
    if RS274 is None:
        pytest.skip("LinuxCNC's rs274 is not installed")
    with tempfile.TemporaryDirectory(prefix="rs274-") as tmp:
        d = Path(tmp)
        prog = d / "prog.ngc"
        prog.write_bytes(text.encode("utf-8", errors="surrogateescape"))
        out = d / "out.txt"
        cmd = [RS274]
        tbl = d / "tools.tbl"
        tbl.write_text(DEFAULT_TOOLS if tools is None else tools)
        cmd += ["-t", str(tbl)]
        var = d / "params.var"
        _write_var_file(var, params or {})
        cmd += ["-v", str(var)]
        if files:  # the INI file costs startup time: only when subroutines are needed
            subs = d / "subs"
            subs.mkdir()
            for name, body in files.items():
                (subs / name).write_bytes(body.encode("utf-8", errors="surrogateescape"))
            ini = d / "rs274.ini"
            ini.write_text(f"[RS274NGC]\nSUBROUTINE_PATH = {subs}\nPARAMETER_FILE = {var}\n")
            cmd += ["-i", str(ini)]
        cmd += ["-g", str(prog), str(out)]
        # HOME: rs274 keeps its tool table in a file mapped into memory, $HOME/.tool.mmap,
        # which it truncates and rewrites at start. Runs sharing one HOME (pytest-xdist
        # workers, another checkout's tests, rs274 typed in a shell) read each other's tool
        # lengths: a G43 H1 then took another run's T1 Z51 (inches), a path 1,295.4 mm off,
        # and a run whose mapping was truncated under it died of SIGBUS. Each run gets its own.
        env = dict(os.environ, LC_ALL="C", HOME=str(d))
        out.unlink(missing_ok=True)
        proc = subprocess.run(cmd, cwd=d, stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout, env=env)
        canon = out.read_text() if out.exists() else ""
    motions, calls = parse_canon(canon)
    err_lines = [ln for ln in (proc.stderr + proc.stdout).splitlines() if ln.strip() and ln.strip() != "executing"]
    ok = proc.returncode == 0
    if proc.returncode < 0:
        err_lines.append(f"rs274 was killed by signal {-proc.returncode}")
    return Rs274Result(ok, "" if ok else "\n".join(err_lines), motions, calls)


def run_rs274_many(texts: list[str], **kw) -> list[Rs274Result]:
    """:func:`run_rs274` on several programs (same options), one after the other."""
    return [run_rs274(t, **kw) for t in texts]


def same_motions(a: list[Motion], b: list[Motion], tol: float = RS274_RESOLUTION * 1.5) -> str:
    """"" when the two lists match motion by motion, else where they first differ."""
    for k, (ma, mb) in enumerate(zip(a, b, strict=False)):
        if not ma.close_to(mb, tol):
            return f"motion {k}: {ma} != {mb}"
    if len(a) != len(b):
        return f"{len(a)} motions != {len(b)} motions"
    return ""


_MACHINE_CALL = re.compile(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED|SET_G5X_OFFSET|SET_G92_OFFSET|"
                           r"USE_TOOL_LENGTH_OFFSET)\(([^)]*)\)")
# sampling of arcs in machine_path (mm of arc length)
ARC_STEP_MM = 0.02


def uses_inches(res: Rs274Result) -> bool:
    """Some of the program's positions are printed in inches (4 decimals: 2.54 um)."""
    return "USE_LENGTH_UNITS(CANON_UNITS_INCHES)" in res.calls


def uses_nurbs(res: Rs274Result) -> bool:
    """The program made splines, whose geometry rs274 does not print."""
    return any(c.startswith("NURBS_FEED") for c in res.calls)


def machine_path(res: Rs274Result, line_step: float | None = None,
                 mm: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(end points of the motions, the path as a dense polyline, which points of that
    polyline end a traverse) in machine coordinates, from an rs274 run.

    Canonical positions are in the program's frame; machine = canonical + G5x + G92 +
    tool length offset, tracked as rs274 announces them. The polyline starts at the first
    motion's end (where the machine came from is unknown); arcs are sampled as LinuxCNC
    draws them (radius and normal axis varying linearly with the angle) every
    :data:`ARC_STEP_MM`; straight feeds are end points only, or sampled every
    ``line_step`` when given. Traverses are always end points only. Positions are as
    printed (in the program's units at each call), or in mm with ``mm`` (converted as
    rs274 announces its units, ``USE_LENGTH_UNITS``)."""
    off = {"G5X": np.zeros(3), "G92": np.zeros(3), "TLO": np.zeros(3)}
    motions = iter(res.motions)
    ends: list[np.ndarray] = []
    path: list[np.ndarray] = []
    rapid: list[np.ndarray] = []
    prev = None
    unit = 1.0
    for call in res.calls:
        if mm and call.startswith("USE_LENGTH_UNITS("):
            unit = 25.4 if "INCHES" in call else 0.1 if "CM" in call else 1.0
        m = _MACHINE_CALL.match(call)
        if m is None:
            continue
        name = m.group(1)
        v = [float(x) * unit for x in re.split(r"[,\s]+", m.group(2).strip()) if x]
        if name == "SET_G5X_OFFSET":
            off["G5X"] = np.array(v[1:4])
            continue
        if name == "SET_G92_OFFSET":
            off["G92"] = np.array(v[:3])
            continue
        if name == "USE_TOOL_LENGTH_OFFSET":
            off["TLO"] = np.array(v[:3])
            continue
        mo = next(motions)
        shift = off["G5X"] + off["G92"] + off["TLO"]
        end = np.array(mo.end[:3]) * unit + shift
        if prev is None:
            pts = end[None, :]
        elif mo.kind == "ARC_FEED":
            a1, a2, an = _PLANE_AXES["CANON_PLANE_" + mo.plane]
            c = np.array(mo.centre) * unit + shift
            t0 = np.arctan2(prev[a2] - c[a2], prev[a1] - c[a1])
            t1 = np.arctan2(end[a2] - c[a2], end[a1] - c[a1])
            r0, r1 = np.hypot(prev[a1] - c[a1], prev[a2] - c[a2]), np.hypot(end[a1] - c[a1], end[a2] - c[a2])
            turns = abs(mo.turn)
            if mo.turn > 0:
                sweep = (t1 - t0) % (2 * np.pi)
                sweep = sweep if sweep > 1e-12 else 2 * np.pi
                sweep += (turns - 1) * 2 * np.pi
            else:
                sweep = -((t0 - t1) % (2 * np.pi))
                sweep = sweep if sweep < -1e-12 else -2 * np.pi
                sweep -= (turns - 1) * 2 * np.pi
            n = max(8, int(np.ceil(abs(sweep) * max(r0, r1) / ARC_STEP_MM)))
            u = np.linspace(0.0, 1.0, n + 1)[1:]
            pts = np.empty((n, 3))
            rad = r0 + (r1 - r0) * u
            pts[:, a1] = c[a1] + rad * np.cos(t0 + sweep * u)
            pts[:, a2] = c[a2] + rad * np.sin(t0 + sweep * u)
            pts[:, an] = prev[an] + (end[an] - prev[an]) * u
        elif mo.kind == "STRAIGHT_FEED" and line_step is not None:
            n = max(1, int(np.ceil(np.linalg.norm(end - prev) / line_step)))
            pts = prev + (end - prev) * (np.arange(1, n + 1) / n)[:, None]
        else:
            pts = end[None, :]
        path.append(pts)
        rapid.append(np.full(len(pts), mo.kind == "STRAIGHT_TRAVERSE" and prev is not None))
        ends.append(end)
        prev = end
    dense = np.vstack(path) if path else np.zeros((0, 3))
    return np.array(ends).reshape(-1, 3), dense, np.concatenate(rapid) if rapid else np.zeros(0, bool)
