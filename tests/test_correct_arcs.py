"""Emitted arcs are exact circles after rounding, follow the corrected ideal path within
--tolerance, and corrected programs stay compact; backlash is taken up at reversals.

The checks are independent of the planning code: the corrected output is read back by
the interpreter (the radii come from the written words), the corrected ideal path is the
engine's correction of the original program's densely sampled nominal path, and path
accuracy is measured on the virtual machine through ``verify``."""

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import PARAMETRIC, STEP, TOL, emitted_arcs, ideal_vs_emitted
from oracle import requires_rs274, run_rs274  # noqa: I001  (the tests' own helper, a sibling module)

from postproc.calfile import load_calibration
from postproc.gcode import emit
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.segment import ArcPiece, arc_candidates
from postproc.simulate.machine import load_machine
from postproc.simulate.program import verify_program

ROOT = Path(__file__).parents[1]
SAMPLES = ROOT / "samples"
CORPUS = Path(__file__).parents[2] / "shared" / "corpus"
GENCAM = Path(__file__).parents[2] / "shared" / "bench" / "gencam.py"
MACHINE = ROOT / "calibrations" / "s500.machine.json"

SAMPLE_CASES = [
    ("pocket.nc", Setup()),
    ("planes.ngc", Setup()),
    ("inch.nc", Setup()),
    ("g54_g43.ngc", Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 100.0})),
]
# corpus programs with arcs (R and IJ, G91.1, inch, tool lengths), placed in the volume
TOOLS = {t: 20.0 for t in range(100)}
CORPUS_CASES = [
    ("pygcode-linuxcnc/Circular_Pocket.tap", Setup(offsets={"G54": (150.0, 150.0, 150.0)}, tool_lengths=TOOLS)),
    ("pygcode-linuxcnc/Smiley001.nc", Setup(offsets={"G54": (100.0, 100.0, 150.0)}, tool_lengths=TOOLS)),
]


def _cases():
    out = [pytest.param(SAMPLES / n, s, id=n) for n, s in SAMPLE_CASES]
    for n, s in CORPUS_CASES:
        out.append(pytest.param(CORPUS / n, s, id=n, marks=pytest.mark.skipif(
            not (CORPUS / n).is_file(), reason="no shared corpus")))
    return out


@pytest.fixture(scope="module")
def parametric():
    return load_calibration(PARAMETRIC)


@pytest.mark.parametrize(("path", "setup"), _cases())
def test_every_emitted_arc_is_one_exact_circle_on_the_ideal_path(path, setup, parametric):
    text = path.read_text(encoding="utf-8", errors="surrogateescape")
    opts = CorrectOptions(extrapolate="clamp")
    out, report = correct_text(text, parametric.engine, setup, opts)
    arcs = emitted_arcs(out, setup)
    assert arcs, "the corrected program keeps arcs"
    for unit, r0, r1, lineno in arcs:
        half = 0.5 * 10.0 ** (-(5 if unit != 1.0 else 4)) * unit
        assert abs(r1 - r0) <= half + 1e-9, (lineno, r0, r1, out.splitlines()[lineno - 1])
    n_in_arcs = len(emitted_arcs(text, setup))
    assert report.arcs_kept + report.arcs_split + report.arcs_linearised == n_in_arcs
    assert ideal_vs_emitted(text, out, parametric.engine, setup) <= TOL


def test_identity_and_uniform_scale_keep_every_arc():
    from postproc.engine.static import StaticEngine

    text = ("G21 G90 G17\nG0 X100 Y100 Z50\nG1 X110 F500\nG3 X100.5 Y108.492 R8.508\n"
            "G3 X92.008000000000000 Y100.000000000000000 I0.000000000000000 J-8.492000000000000 (15 decimals)\n"
            "G3 X110 Y100 I8.996 J0\nM2\n")
    ident = StaticEngine(np.eye(3), [0, 0, 0], [[0] * 3, [300] * 3])
    out, rep = correct_text(text, ident, Setup(), CorrectOptions())
    assert emit.split_header(out)[1] == text
    assert rep.arcs_kept == 3
    assert rep.lines_inserted == 0
    # a uniform scale maps circles to circles: every arc stays one arc
    scale = StaticEngine(np.eye(3) * (1 + 200e-6), [0, 0, 0], [[0] * 3, [300] * 3])
    out, rep = correct_text(text, scale, Setup(), CorrectOptions())
    assert rep.arcs_kept == 3
    assert rep.lines_inserted == 0
    for unit, r0, r1, lineno in emitted_arcs(out, Setup()):
        assert abs(r1 - r0) <= 0.5e-4 * unit + 1e-9, out.splitlines()[lineno - 1]
    assert ideal_vs_emitted(text, out, scale, Setup()) <= TOL


def _model_error(program: str, machine, engine, setup: Setup) -> float:
    """How far the calibration's own ideal correction lands from the nominal path on the machine."""
    nom = program_path(program, setup, max_step_mm=STEP)
    feed = ~nom.rapid
    q = nom.points_mm - nom.tool_mm
    ideal = q + np.asarray(engine.correction(nom.points_mm, nom.tool_mm, nom.context).q)
    actual = machine.forward(ideal, nom.tool_mm, nom.context)
    return float(np.linalg.norm(actual - nom.points_mm, axis=1)[feed].max())


ARCS_PROGRAM = """G21 G90 G17
G0 X120 Y100 Z60
G1 Z50 F300
G1 X160 F800
(large radius, short chord: R 735 mm, chord 4.4 mm)
G2 X164.4 Y100 R735.0
G3 X168.8 Y100 I2.2 J734.9967
(input radius mismatch: end radius 8 um longer than the start radius, IJ rounded by a CAM post)
G3 X176.808 Y108 I0 J8.0
G2 X190.808 Y122 I14 J0
G3 X150.808 Y122 I-20 J0.0
G1 Y110
G2 X150.808 Y110 I10 J10 (full circle)
G0 Z60
M2
"""


@pytest.mark.parametrize("name", ["pocket.nc", "arcs"])
def test_path_accuracy_on_the_virtual_machine(name, parametric, tmp_path):
    machine = load_machine(MACHINE)
    if name == "arcs":
        prog = tmp_path / "arcs.nc"
        prog.write_text(ARCS_PROGRAM)
    else:
        prog = SAMPLES / name
    rep = verify_program(prog, machine, [parametric])
    before, after = rep.runs
    model = _model_error(str(prog), machine, parametric.engine, Setup())
    assert before.max_mm > 0.1
    assert after.max_mm <= model + TOL, (after.max_mm, model)
    text = prog.read_text()
    out, _ = correct_text(text, parametric.engine, Setup(), CorrectOptions())
    for unit, r0, r1, lineno in emitted_arcs(out, Setup()):
        assert abs(r1 - r0) <= 0.5e-4 * unit + 1e-9, out.splitlines()[lineno - 1]


def test_output_stays_compact(parametric, tmp_path):
    text = (SAMPLES / "pocket.nc").read_text()
    _out, rep = correct_text(text, parametric.engine, Setup(), CorrectOptions())
    assert rep.growth <= 3.0, rep.growth
    if not GENCAM.is_file():
        pytest.skip("no shared bench generator")
    prog = tmp_path / "cam.nc"
    subprocess.run([sys.executable, str(GENCAM), "800", str(prog), "7"], check=True, capture_output=True)
    setup = Setup(offsets={"G54": (10.0, 10.0, 100.0)}, tool_lengths={t: 50.0 + t for t in range(1, 21)})
    # O-words and G28 are refused: the generator's program header and end go
    text = "".join(ln for ln in prog.read_text().splitlines(keepends=True) if not ln.startswith(("O", "G28")))
    out, rep = correct_text(text, parametric.engine, setup, CorrectOptions())
    assert rep.growth <= 2.0, rep.growth
    assert ideal_vs_emitted(text, out, parametric.engine, setup) <= TOL


class _Walkthrough:
    """The walkthrough's virtual machine: the static machine with its 12 um lost motion on X."""

    def __init__(self, backlash: bool = True) -> None:
        from postproc.diagnose import demo

        self.base, self.effects = demo.walkthrough_machine()
        if not backlash:
            self.effects = []

    def forward(self, q, r=None, context=None):
        q = np.asarray(q, dtype=float)
        r = np.zeros_like(q) if r is None else np.asarray(r, dtype=float)
        out = self.base.forward(q, r)
        for e in self.effects:
            out = out + e.displacement(q, r, context)
        return out


def test_walkthrough_backlash_calibration_corrects_the_pocket(tmp_path, monkeypatch):
    from click.testing import CliRunner

    from postproc.cli import main

    monkeypatch.chdir(tmp_path)
    walk = ROOT / "samples" / "walkthrough_points.csv"
    runner = CliRunner()
    for args in (["fit", str(walk), "--method", "static", "-o", "static.json"],
                 ["fit", str(walk), "--method", "static", "--effect", "backlash:X", "-o", "backlash.json"],
                 ["correct", str(SAMPLES / "pocket.nc"), "-c", "backlash.json", "-o", "pocket_b.nc"]):
        res = runner.invoke(main, args)
        assert res.exit_code == 0, res.output
    assert "growth" in res.output
    machine = _Walkthrough()
    rep = verify_program(SAMPLES / "pocket.nc", machine, [load_calibration(tmp_path / "static.json")],
                         corrected=None)
    static = rep.runs[1]
    with_b = verify_program(SAMPLES / "pocket.nc", machine, [], corrected=tmp_path / "pocket_b.nc").runs[1]

    def beyond(run, limit):
        return float(np.mean(run.deviation_mm[run.feed] > limit))

    # without the backlash in the calibration half the path is off by about b/2
    assert static.max_mm >= 0.006
    assert beyond(static, 0.002) > 0.4
    # with it, the path lands within 2 um everywhere, reversals included: X lags (lost
    # motion, b < 0), each take-up moves in the new direction, and every direction the
    # correction assumed is one the corrected commands take (rapids and plunges whose
    # correction moves X included)
    assert with_b.max_mm <= 0.002
    out = (tmp_path / "pocket_b.nc").read_text()
    assert "G1 X" in out  # take-ups
    for unit, r0, r1, lineno in emitted_arcs(out, Setup()):
        assert abs(r1 - r0) <= 0.5e-4 * unit + 1e-9, out.splitlines()[lineno - 1]


def test_periodic_lead_screw_error_is_followed_along_moves_and_arcs():
    from postproc.effects import compose
    from postproc.engine.static import StaticEngine

    base = StaticEngine(np.eye(3), [0, 0, 0], [[0] * 3, [315] * 3])
    eng = compose(base, [{"name": "periodic:X", "config": {"pitch_mm": 5.0},
                          "params": {"cos_mm": 0.004, "sin_mm": -0.003}}])
    text = ("G21 G90 G17\nG0 X100 Y100 Z50\nG1 Z40 F300\nG1 X160 Y110 F800\n"
            "G2 X160 Y90 I0 J-10\nG3 X140 Y70 R20\nG1 X100 Y100\nG0 Z60\nM2\n")
    out, rep = correct_text(text, eng, Setup(), CorrectOptions())
    # the 5 um screw wave is followed within the tolerance, by far fewer lines than halving gave
    assert ideal_vs_emitted(text, out, eng, Setup()) <= TOL
    uncorrected = program_path(text, Setup(), max_step_mm=STEP)
    assert rep.lines_out < 200
    assert np.abs(np.asarray(eng.correction(uncorrected.points_mm, uncorrected.tool_mm,
                                            uncorrected.context).q)).max() > 0.004
    for unit, r0, r1, lineno in emitted_arcs(out, Setup()):
        assert abs(r1 - r0) <= 0.5e-4 * unit + 1e-9, out.splitlines()[lineno - 1]


# Arcs whose fitted centre a controller refused or misread: chords of a few output steps (a
# 0.9 mm arc 0.6 um long, from a real program; 0.0005 in corner arcs 1e-5 in long, which
# became circles of 0.7 um and of 6 km) and a 2730 mm arc 0.28 mm long that bows 3.6 nm
# from its chord.
TINY_MM = ("G21 G90 G17\nG0 X20.0923 Y27.7201 Z5\nG1 Z-0.3 F300\nG3 X20.0929 Y27.7202 I-0.1031 J0.8941\n"
           "G1 X10.4066 Y39.7626\nG2 X10.2729 Y40.0111 I2404.193 J1293.8208\nG2 X20.2729 I5 J0\nM2\n")
TINY_INCH = ("G20 G90 G17\nG0 X-1.839332 Y1.06599 Z0.1\nG1 Z-0.05 F15\nG3 X-1.839333 Y1.066 I-0.000497 J-0.000058\n"
             "G2 X-1.78474 Y1.285138 I0.301344 J0.041296\nG2 X-1.587205 Y1.397775 I0.243525 J-0.197547\n"
             "G3 X-1.587193 Y1.397777 I-0.000073 J0.000495\nM2\n")
# LinuxCNC: "Zero-radius arc" below 0.00005 in (= 0.00127 mm); its motion (and Grbl) cut an
# arc whose sweep is within 1e-6 rad (5e-7 rad) of zero as a full circle
LINUXCNC_MIN_RADIUS_MM = 0.00005 * 25.4


def _scaled(text: str, bulk_plan: bool = True):
    from postproc.engine.static import StaticEngine

    eng = StaticEngine(np.eye(3) * 1.0002, [0, 0, 0], [[-1e6] * 3, [1e6] * 3])
    out, rep = correct_text(text, eng, Setup(), CorrectOptions(bulk_plan=bulk_plan))
    return eng, out, rep


@pytest.mark.parametrize("bulk_plan", [True, False], ids=["bulk", "sampled"])
@pytest.mark.parametrize(("text", "n_arcs"), [(TINY_MM, 3), (TINY_INCH, 4)], ids=["mm", "inch"])
def test_tiny_and_flat_arcs_under_a_scale_stay_arcs_that_controllers_draw(text, n_arcs, bulk_plan):
    eng, out, rep = _scaled(text, bulk_plan)
    interp = Interpreter(Setup(), None)
    seen = 0
    for lineno, line in enumerate(out.splitlines(keepends=True), start=1):
        mv = interp.feed_line(lineno, line)
        if mv is None or mv.arc is None:
            continue
        seen += 1
        c = mv.arc.center
        r0 = math.hypot(mv.q0[0] - c[0], mv.q0[1] - c[1])
        r1 = math.hypot(mv.q1[0] - c[0], mv.q1[1] - c[1])
        t0 = math.atan2(mv.q0[1] - c[1], mv.q0[0] - c[0])
        t1 = math.atan2(mv.q1[1] - c[1], mv.q1[0] - c[0])
        sweep = (t0 - t1) % (2 * math.pi) if mv.arc.clockwise else (t1 - t0) % (2 * math.pi)
        assert min(r0, r1) >= LINUXCNC_MIN_RADIUS_MM, line
        assert sweep >= 1e-5, line
        assert abs(r1 - r0) <= 0.5 * 10.0 ** (-(5 if mv.unit != 1.0 else 4)) * mv.unit + 1e-9, line
    # a uniform scale keeps circles circles: every arc stays one arc
    assert seen == n_arcs
    assert (rep.arcs_kept, rep.arcs_linearised, rep.arcs_split, rep.lines_inserted) == (n_arcs, 0, 0, 0)
    assert ideal_vs_emitted(text, out, eng, Setup()) <= TOL


@requires_rs274
@pytest.mark.parametrize("bulk_plan", [True, False], ids=["bulk", "sampled"])
@pytest.mark.parametrize("text", [TINY_MM, TINY_INCH], ids=["mm", "inch"])
def test_linuxcnc_runs_the_corrected_tiny_arcs(text, bulk_plan):
    assert run_rs274(text).ok  # the input itself loads
    _eng, out, rep = _scaled(text, bulk_plan)
    res = run_rs274(out)
    assert res.ok, res.error
    assert sum(m.kind == "ARC_FEED" for m in res.motions) == rep.arcs_kept


def test_arc_candidates_with_controller_limits_refuse_zero_radius_and_flat_arcs():
    S, E = np.array([0.0, 0.0, 0.0]), np.array([0.001, 0.0, 0.0])
    Q = np.array([S, 0.5 * (S + E), E])
    frac = np.array([0.0, 0.5, 1.0])
    # centres (hand-placed on the bisector x = 0.0005): radius 0.00112 mm (below
    # LinuxCNC's 0.00127 mm), 0.0013 mm, and 1000 mm (sweep 1e-6 rad)
    C = np.array([[0.0005, -0.001], [0.0005, -math.sqrt(0.0013 ** 2 - 0.0005 ** 2)], [0.0005, -1000.0]])
    sweeps = [2 * math.asin(0.0005 / math.hypot(*c)) for c in C]
    assert sweeps[2] < 1e-5 < sweeps[1]
    # clockwise from S over the top of each centre
    loose, _m, _t = arc_candidates(ArcPiece(S, E, (0, 1, 2), True, -sweeps[1], Q, frac), C)
    strict, _m, _t = arc_candidates(ArcPiece(S, E, (0, 1, 2), True, -sweeps[1], Q, frac), C, controller_limits=True)
    assert np.isfinite(loose).all()
    assert np.isinf(strict[[0, 2]]).all()
    assert strict[1] == loose[1]


def test_a_bulk_planned_arc_is_held_to_the_controller_limits():
    from arcwords_reference import spec as spec_without_limits

    from postproc.gcode.vplan import ArcHint

    # a chord of 0.3 um: the bulk planner's circle through the ends, fitted to rounding
    # noise 6 km away on the bisector, passes its own deviation bound, but the sweep
    # (5e-11 rad) is one LinuxCNC and Grbl cut as a whole circle
    interp = Interpreter(Setup(), None)
    interp.feed_line(1, "G21 G90 G17 G0 X10 Y10 Z0\n")
    mv = interp.feed_line(2, "G3 X10.0003 Y10 I0.00015 J0.0005\n")
    S, E = [10.0, 10.0, 0.0], [10.0003, 10.0, 0.0]
    far = ArcHint(10.00015, 10.0 + 6e6, 6e6, 0.0, 5e-11, (10.0, 10.0, 0.0, 10.0003, 10.0, 0.0), -1)
    assert spec_without_limits(far, mv, S, E, 4, 0.00095) is not None  # the bound alone passes it
    assert far.spec(mv, S, E, 4, 0.00095) is None
    # limits by hand, on exact circles about the origin (centre words 0, bound 0):
    # radius 0.0013 mm passes, 0.0012 mm does not; a sweep of 2e-5 rad passes, 5e-6 rad
    # does not, either way round
    axes, base, budget = (0, 1, 2), (0.0, 0.0), 0.00095

    def words(S, E, sweep, clockwise):
        rho = math.hypot(S[0], S[1])
        hint = ArcHint(0.0, 0.0, rho, 0.0, -sweep if clockwise else sweep, (*S, *E), -1)
        return hint.words(S, E, axes, clockwise, 4, 1.0, base, budget)

    for r, ok in ((0.0013, True), (0.0012, False)):
        got = words([r, 0.0, 0.0], [0.0, r, 0.0], math.pi / 2, False)
        assert (got is not None and got[:2] == (0.0, 0.0)) is ok
    for sweep, ok in ((2e-5, True), (5e-6, False)):
        end = [100 * math.cos(sweep), 100 * math.sin(sweep), 0.0]
        assert (words([100.0, 0.0, 0.0], end, sweep, False) is not None) is ok
        assert (words(end, [100.0, 0.0, 0.0], sweep, True) is not None) is ok


def test_growth_counts_the_program_not_the_header(tmp_path):
    """A short program corrected with many tool lengths gets a long header (the setup);
    the growth and its warning count the program's own lines."""
    from click.testing import CliRunner

    from postproc.cli import main

    prog = tmp_path / "short.nc"
    prog.write_text("G21 G90 G17\nG0 X100 Y100 Z120\nG1 X110 F500\nM2\n")
    tools = [a for t in range(1, 41) for a in ("--tool-length", f"{t}=50")]
    res = CliRunner().invoke(main, ["correct", str(prog), "-c", str(ROOT / "calibrations" / "s500_static.json"),
                                    "-o", str(tmp_path / "out.nc"), *tools])
    assert res.exit_code == 0, res.output
    m = re.search(r"growth (\d+) / 4 lines = ([\d.]+)x \(\+(\d+) header lines\)", res.output)
    assert m, res.output
    body, header = int(m.group(1)), int(m.group(3))
    out = (tmp_path / "out.nc").read_text().splitlines()
    assert header == len(emit.split_header("\n".join(out) + "\n")[0]) > 4
    assert body + header == len(out)
    assert body == 4
    assert "warning" not in res.output
