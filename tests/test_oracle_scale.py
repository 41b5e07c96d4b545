"""LinuxCNC's own interpreter as the oracle: every sample and corpus program that rs274
accepts, corrected for a machine that moves k times what it is told (a uniform scale about
the machine origin, so circles stay circles and nothing needs splitting), must be accepted
by rs274 too: every canonical end point of the original, divided by k, must lie on the
corrected program's path, and the two paths (arcs drawn as LinuxCNC draws them) must stay
within the tolerance and rs274's print rounding of each other both ways, in mm.

Programs run with every work offset zero, tool lengths zero and the stored G28/G30
positions at the origin, so that program and machine coordinates coincide."""

from pathlib import Path

import numpy as np
import pytest
from conftest import corpus_programs, polyline_distance
from oracle import _PLANE_AXES, RS274, machine_path, run_rs274, uses_nurbs  # noqa: I001  (the tests' own helper, a sibling module)

from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CORPUS = Path(__file__).parents[2] / "shared" / "corpus"
EXTS = {".nc", ".ngc", ".tap", ".gcode"}
K = 1.0002
# Longer corpus programs are run through the oracle by benchmarks/corpus_oracle.py (rs274
# takes under a second on them, but correcting and comparing the 15 take minutes in all).
MAX_LINES = 10_000

pytestmark = pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 is not installed")


# Known defects found by this oracle, left open (each fails today; strict, so a fix shows):
KNOWN_DEFECTS: dict[str, str] = {}


def _programs():
    files = sorted(p for p in (ROOT / "samples").rglob("*") if p.suffix.lower() in EXTS)
    files = [p for p in files if p.read_bytes().count(b"\n") <= MAX_LINES]
    # every corpus program with POSTPROC_FULL_CORPUS=1, else a subset naming every
    # construct, source and suffix they name (conftest.representative)
    files += corpus_programs(max_lines=MAX_LINES)
    out = []
    for p in files:
        reason = KNOWN_DEFECTS.get(p.name)
        out.append(pytest.param(p, marks=pytest.mark.xfail(strict=True, reason=reason)) if reason else p)
    return out


TOOLS = "".join(f"T{t} P{t} Z0 D0 ;\n" for t in range(1, 100))


def rs274(text: str, tmp: Path):
    """(accepted, end points of the motions in machine mm, the path sampled as a dense
    polyline in machine mm, error, the step of the positions rs274 printed in mm,
    :func:`unresolved_arcs`) of ``text`` run through rs274. It prints 4 decimals in the
    program's units: 0.1 um steps in mm, 2.54 um in inches."""
    res = run_rs274(text, tools=TOOLS)
    if uses_nurbs(res):
        pytest.skip("rs274 prints no geometry for splines (NURBS_FEED): the original path is unknown")
    ends, dense, _ = machine_path(res, mm=True)
    inch = any(c.startswith("USE_LENGTH_UNITS(CANON_UNITS_INCHES") for c in res.calls)
    return res.ok, ends, dense, res.error, (25.4e-4 if inch else 1e-4), unresolved_arcs(res, inch)


def unresolved_arcs(res, inch: bool) -> float:
    """Twice the largest radius (mm) of an arc whose start and end rs274 printed alike:
    the print cannot tell such an arc (a few micrometres of chord in inches) from the full
    circle the path is then drawn as, so the drawn path may stray by its diameter."""
    worst = 0.0
    prev = None
    for mo in res.motions:
        if mo.kind == "ARC_FEED" and prev is not None and abs(mo.turn) == 1:
            a1, a2, _ = _PLANE_AXES["CANON_PLANE_" + mo.plane]
            if mo.end[a1] == prev[a1] and mo.end[a2] == prev[a2]:
                r = float(np.hypot(prev[a1] - mo.centre[a1], prev[a2] - mo.centre[a2]))
                worst = max(worst, 2 * r * (25.4 if inch else 1.0))
        prev = mo.end
    return worst


def _setup():
    offsets = {n: (0.0, 0.0, 0.0) for n in ["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"]}
    return Setup(offsets=offsets, tool_lengths={t: 0.0 for t in range(100)},
                 home={"G28": {"X": 0.0, "Y": 0.0, "Z": 0.0}, "G30": {"X": 0.0, "Y": 0.0, "Z": 0.0}})


@pytest.mark.parametrize("path", _programs(), ids=lambda p: f"{p.parent.name}/{p.name}" if isinstance(p, Path) else None)
def test_scaled_program_lands_every_canonical_point_on_the_original_over_k(path, tmp_path):
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    ok, ref_ends, ref_path, _, step, blur = rs274(text, tmp_path)
    if not ok or not len(ref_ends):
        pytest.skip("rs274 does not run the original program")
    eng = StaticEngine(K * np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    try:
        out, _ = correct_text(text, eng, _setup(), CorrectOptions(dialect="linuxcnc", cycles="expand"),
                              path=str(path))
    except PostprocError as exc:
        pytest.skip(f"refused: {exc.message}")
    ok2, got_ends, got_path, log, step2, blur2 = rs274(out, tmp_path)
    assert ok2, log[-500:]
    # the corrected program, run by LinuxCNC, must make the original's path over k: every
    # canonical end point of the original (over k) lies on the corrected path, and the two
    # paths (arcs drawn as LinuxCNC draws them) stay within the correction tolerance of
    # each other, both ways, compared in mm. rs274 prints 4 decimals in the program's
    # units: half a step of rounding on each side (0.05 um in mm, 1.27 um in inches),
    # a whole step allowed for each; and an arc the print cannot resolve, by its diameter.
    tol = CorrectOptions().tolerance_mm + 2 * max(step, step2) + max(blur, blur2)
    target = ref_path / K
    assert polyline_distance(ref_ends / K, got_path).max() <= tol
    assert polyline_distance(got_path, target).max() <= tol
    assert polyline_distance(target, got_path).max() <= tol


def test_rs274_runs_keep_their_tool_table_to_themselves(tmp_path, monkeypatch):
    """rs274 maps its tool table from $HOME/.tool.mmap: runs sharing a HOME read each
    other's tool lengths (this test file's flaky 1,295.4 mm: another run's T1 Z51 in
    inches). Each run_rs274 has a HOME of its own, and runs at the same time each keep
    their own tool length."""
    from concurrent.futures import ThreadPoolExecutor

    monkeypatch.setenv("HOME", str(tmp_path))
    text = "G20 G90\nT1 M6\nG43 H1\nG0 X1 Z1\nM2\n"

    def tool_offset(z: int) -> str:
        res = run_rs274(text, tools=f"T1 P1 Z{z} D0\n")
        assert res.ok, res.error
        return next(c for c in res.calls if c.startswith("USE_TOOL_LENGTH_OFFSET"))

    with ThreadPoolExecutor(4) as pool:
        got = list(pool.map(tool_offset, [0, 51] * 12))
    assert not (tmp_path / ".tool.mmap").exists()
    assert all(g.split(",")[0].endswith(" 0.0000") for g in got[0::2])
    assert all(g.split(",")[0].endswith(" 51.0000") for g in got[1::2])
