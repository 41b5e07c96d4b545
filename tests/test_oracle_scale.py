"""LinuxCNC's own interpreter as the oracle: every sample and corpus program that rs274
accepts, corrected for a machine that moves k times what it is told (a uniform scale about
the machine origin, so circles stay circles and nothing needs splitting), must be accepted
by rs274 too, and every canonical end point and arc centre must be the original's divided
by k, within the output rounding.

Programs run with every work offset zero, tool lengths zero and the stored G28/G30
positions at the origin, so that program and machine coordinates coincide."""

import re
from pathlib import Path

import numpy as np
import pytest
from oracle import RS274, run_rs274  # noqa: I001  (the tests' own helper, a sibling module)

from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CORPUS = Path(__file__).parents[2] / "shared" / "corpus"
EXTS = {".nc", ".ngc", ".tap", ".gcode"}
K = 1.0002
MAX_LINES = 10_000  # longer corpus programs: benchmarks/corpus_survey.py --oracle
_CANON = re.compile(r"(STRAIGHT_TRAVERSE|STRAIGHT_FEED|ARC_FEED|SET_G5X_OFFSET|SET_G92_OFFSET|"
                    r"USE_TOOL_LENGTH_OFFSET)\(([^)]*)\)")

pytestmark = pytest.mark.skipif(RS274 is None, reason="LinuxCNC's rs274 is not installed")


def _programs():
    files = sorted(p for p in (ROOT / "samples").rglob("*") if p.suffix.lower() in EXTS)
    if CORPUS.is_dir():
        files += sorted(p for p in CORPUS.rglob("*") if p.suffix.lower() in EXTS)
    out = []
    for p in files:
        with open(p, "rb") as fh:
            if sum(1 for _ in fh) <= MAX_LINES:
                out.append(p)
    return out


TOOLS = "".join(f"T{t} P{t} Z0 D0 ;\n" for t in range(1, 100))


def rs274(text: str, tmp: Path):
    """(accepted, motions in machine coordinates, error) of ``text`` run through rs274."""
    res = run_rs274(text, tools=TOOLS)
    # canonical positions are in the program's frame; machine = canonical + G5x + G92 +
    # tool length offset, tracked as rs274 announces them
    motions = []
    g5x = np.zeros(3)
    g92 = np.zeros(3)
    tlo = np.zeros(3)
    for call in res.calls:
        m = _CANON.match(call)
        if m is None:
            continue
        name = m.group(1)
        v = [float(x) for x in re.split(r"[,\s]+", m.group(2).strip()) if x]
        if name == "SET_G5X_OFFSET":
            g5x = np.array(v[1:4])
        elif name == "SET_G92_OFFSET":
            g92 = np.array(v[:3])
        elif name == "USE_TOOL_LENGTH_OFFSET":
            tlo = np.array(v[:3])
        elif name == "ARC_FEED":
            # first_end, second_end, first_axis, second_axis, rotation, axis_end, a, b, c (G17)
            off = g5x + g92 + tlo
            motions.append(("ARC", tuple(np.array([v[0], v[1], v[5]]) + off), tuple(np.array(v[2:4]) + off[:2]),
                            int(v[4])))
        else:
            motions.append((name, tuple(np.array(v[:3]) + g5x + g92 + tlo), None, 0))
    return res.ok, motions, res.error


def _setup():
    offsets = {n: (0.0, 0.0, 0.0) for n in ["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"]}
    return Setup(offsets=offsets, tool_lengths={t: 0.0 for t in range(100)},
                 home={"G28": {"X": 0.0, "Y": 0.0, "Z": 0.0}, "G30": {"X": 0.0, "Y": 0.0, "Z": 0.0}})


@pytest.mark.parametrize("path", _programs(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_scaled_program_lands_every_canonical_point_on_the_original_over_k(path, tmp_path):
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    ok, ref, _ = rs274(text, tmp_path)
    if not ok or not ref:
        pytest.skip("rs274 does not run the original program")
    eng = StaticEngine(K * np.eye(3), np.zeros(3), [[-1e6] * 3, [1e6] * 3])
    try:
        out, _ = correct_text(text, eng, _setup(), CorrectOptions(dialect="linuxcnc", cycles="expand"),
                              path=str(path))
    except PostprocError as exc:
        pytest.skip(f"refused: {exc.message}")
    ok2, got, log = rs274(out, tmp_path)
    assert ok2, log[-500:]
    inch = bool(re.search(r"(?i)G20(?!\d)", text))
    # rs274 prints 4 decimals; the corrected words are rounded to 4 (mm) or 5 (inch) decimals
    tol = 1.2e-4 if not inch else 1.2e-4
    ref_pts = [(kind, p, c) for kind, p, c, _ in ref]
    got_pts = [(kind, p, c) for kind, p, c, _ in got]
    assert [k for k, _, _ in got_pts] == [k for k, _, _ in ref_pts]
    for (_, p, c), (_, q, d) in zip(ref_pts, got_pts, strict=True):
        assert np.allclose(np.array(p) / K, q, atol=tol + 1e-4 * 0), (p, q)
        if c is not None:
            assert np.allclose(np.array(c) / K, d, atol=tol), (c, d)
