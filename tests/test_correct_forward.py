"""Corrected programs pushed through the forward model land on the nominal path."""

from pathlib import Path

import numpy as np
import pytest
from conftest import corpus_programs, landing_error, polyline_distance

from postproc.engine.base import Engine, InverseResult, check_points, check_tool_vectors
from postproc.engine.static import StaticEngine
from postproc.gcode import emit
from postproc.gcode.lexer import split_lines
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
SAMPLES = ROOT / "samples"
TOL = 0.001
VOLUME = [[0.0, 0.0, 0.0], [315.0, 315.0, 315.0]]
# tests: a machine ten times worse than the demo calibration, so that a program that
# was not corrected misses the path by far more than the tolerance
G_BAD = np.array([[1 + 300e-6, 900e-6, -600e-6], [0.0, 1 - 200e-6, 1000e-6], [0.0, 0.0, 1 + 150e-6]])


def static_engine() -> StaticEngine:
    return StaticEngine(G_BAD, [0.035, -0.022, 0.018], VOLUME)


class WavyEngine(Engine):
    """Test-only non-affine machine: a smooth curved error field of 20 um amplitude."""

    method = "wavy"
    affine = False
    AMP = 0.02

    def _err(self, q):
        return self.AMP * np.column_stack([np.sin(q[:, 1] / 7.0), np.sin(q[:, 0] / 9.0),
                                           np.sin((q[:, 0] + q[:, 1]) / 11.0)])

    def forward(self, q, r=None, context=None):
        q = check_points(q)
        return q + self._err(q) + check_tool_vectors(r, len(q))

    def inverse(self, p, r=None, context=None):
        p = check_points(p)
        rr = check_tool_vectors(r, len(p))
        q = p - rr
        for _ in range(30):
            q = p - rr - self._err(q)
        resid = np.linalg.norm(self.forward(q, rr) - p, axis=1)
        return InverseResult(q, resid, np.full(len(p), 30))

    def model_to_dict(self):
        return {}

    @classmethod
    def model_from_dict(cls, model, volume_mm):
        return cls(volume_mm)


def test_polyline_distance_is_exact():
    rng = np.random.default_rng(12)

    def brute(points, poly):
        a, ab = poly[:-1], np.diff(poly, axis=0)
        t = np.clip(np.einsum("pkj,kj->pk", points[:, None, :] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-30),
                    0.0, 1.0)
        return np.linalg.norm(points[:, None, :] - (a[None] + t[..., None] * ab[None]), axis=2).min(axis=1)

    # a 0.28 mm segment between two passes 0.1 mm above and below it, each sampled every
    # 0.02 mm: the segment's own end points are farther from its middle than many samples
    # of the other passes
    x = np.linspace(0.0, 0.28, 15)
    above = np.column_stack([x, np.zeros_like(x), np.full_like(x, 0.1)])
    below = above * [1, 1, -1]
    poly = np.vstack([above, [[0.0, 0.0, 0.0], [0.28, 0.0, 0.0]], below])
    mid = np.array([[0.14, 0.0, 0.0], [0.07, 0.0002, 0.0]])
    assert np.allclose(polyline_distance(mid, poly), [0.0, 0.0002], atol=1e-15)
    for _ in range(100):
        n = int(rng.integers(2, 60))
        poly = np.cumsum(rng.normal(size=(n, 3)) * rng.choice([1e-3, 0.05, 1.0, 5.0], size=(n, 1)), axis=0)
        pts = poly[rng.integers(0, n, 40)] + rng.normal(size=(40, 3)) * rng.choice([1e-3, 0.1, 3.0])
        assert np.allclose(polyline_distance(pts, poly, step=float(rng.choice([0.01, 0.05, 1.0]))),
                           brute(pts, poly), rtol=0.0, atol=1e-12)


CASES = [
    ("pocket.nc", Setup()),
    ("holes_g91.nc", Setup()),
    ("inch.nc", Setup()),
    ("planes.ngc", Setup()),
    ("g54_g43.ngc", Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 100.0})),
]


@pytest.mark.parametrize(("name", "setup"), CASES, ids=[c[0] for c in CASES])
def test_static_correction_lands_on_the_nominal_path(name, setup):
    text = (SAMPLES / name).read_text()
    eng = static_engine()
    out, report = correct_text(text, eng, setup, CorrectOptions(tolerance_mm=TOL))
    assert report.words_changed > 0
    assert landing_error(text, out, eng, setup) <= TOL * 1.01
    # the same program uncorrected misses by far more (the check can fail)
    assert landing_error(text, text, eng, setup) > 20 * TOL


@pytest.mark.parametrize("name", ["pocket.nc", "planes.ngc", "holes_g91.nc"])
def test_non_affine_engine_splits_lines_and_linearises_arcs(name):
    text = (SAMPLES / name).read_text()
    eng = WavyEngine(VOLUME)
    out, report = correct_text(text, eng, Setup(), CorrectOptions(tolerance_mm=TOL))
    assert report.lines_inserted > 0
    assert landing_error(text, out, eng, Setup(), step=0.02) <= TOL * 1.01
    assert landing_error(text, text, eng, Setup()) > 10 * TOL


def test_tolerance_controls_the_number_of_inserted_lines():
    text = (SAMPLES / "pocket.nc").read_text()
    eng = WavyEngine(VOLUME)
    _, fine = correct_text(text, eng, Setup(), CorrectOptions(tolerance_mm=0.001))
    out, coarse = correct_text(text, eng, Setup(), CorrectOptions(tolerance_mm=0.005))
    assert coarse.lines_inserted < fine.lines_inserted
    assert landing_error(text, out, eng, Setup(), step=0.02) <= 0.005 * 1.01


def test_g91_increments_sum_to_the_corrected_points_without_drift():
    # 2000 tiny incremental steps: rounding each increment independently would drift
    body = "G21 G90 G0 X10 Y10 Z10\nG91\n" + "G1 X0.1 Y0.05 F100\n" * 2000 + "G90\n"
    eng = static_engine()
    out, _ = correct_text(body, eng, Setup(), CorrectOptions())
    pp = program_path(out, Setup(), max_step_mm=1000)
    actual = eng.forward(pp.points_mm - pp.tool_mm, pp.tool_mm)
    nominal = program_path(body, Setup(), max_step_mm=1000).points_mm
    assert np.abs(actual - nominal).max() < 2e-4
    assert "G91" in out


@pytest.mark.parametrize("name", ["pocket.nc", "planes.ngc", "inch.nc"])
def test_arcs_are_kept_when_the_corrected_arc_is_still_an_arc(name):
    # uniform scale plus a shift maps circles to circles: every arc must stay an arc
    eng = StaticEngine(np.eye(3) * (1 + 80e-6), [0.03, -0.02, 0.01], VOLUME)
    text = (SAMPLES / name).read_text()
    out, report = correct_text(text, eng, Setup(), CorrectOptions())
    assert report.arcs_linearised == 0
    assert report.arcs_kept > 0
    assert report.lines_inserted == 0
    assert landing_error(text, out, eng, Setup()) <= TOL * 1.01


def test_demo_calibration_keeps_small_arcs_and_lands():
    from postproc.calfile import load_calibration

    cal = load_calibration(ROOT / "tests" / "cases" / "demo_static.json")
    text = (SAMPLES / "pocket.nc").read_text()
    out, report = correct_text(text, cal.engine, Setup(), CorrectOptions())
    assert report.arcs_kept >= 8  # the 8 mm corner radii stay arcs
    assert landing_error(text, out, cal.engine, Setup()) <= TOL * 1.01


def test_modal_arc_after_a_split_arc_keeps_its_motion():
    # the strong squareness makes both circles ellipses: each is followed by two exact arcs
    text = "G21 G90 G17\nG0 X100 Y100 Z50\nG1 Z40 F300\nG2 X120 Y120 I20 J0\nX120.2 Y120.2 I0.1 J0.1\nG1 X130\n"
    eng = static_engine()
    out, rep = correct_text(text, eng, Setup(), CorrectOptions())
    assert rep.arcs_linearised == 0
    assert rep.arcs_split == 2
    from postproc.gcode import emit

    lines = emit.split_header(out)[1].splitlines()
    assert all(ln.startswith("G2 X") for ln in lines[3:6])
    assert lines[6].startswith("X")  # the modal arc line stays modal: the controller is in G2
    # fine sampling: the polylines must follow a 0.14 mm radius to well under 1 um
    assert landing_error(text, out, eng, Setup(), step=0.002) <= TOL * 1.01


CORPUS = Path(__file__).parents[2] / "shared" / "corpus"


# Longer corpus programs take minutes each at this sampling; they are covered by
# benchmarks/arc_output.py and benchmarks/corpus_survey.py, not by the suite.
CORPUS_MAX_LINES = 600


def _corpus_files():
    # every one with POSTPROC_FULL_CORPUS=1, else a subset naming every construct, source
    # and suffix they name (conftest.representative)
    return corpus_programs(max_lines=CORPUS_MAX_LINES)


@pytest.mark.parametrize("path", _corpus_files(), ids=lambda p: p.name)
def test_corpus_programs_land_on_their_nominal_path(path):
    from conftest import CORPUS_START, corpus_setup

    from postproc.errors import PostprocError

    setup = corpus_setup(path)
    eng = StaticEngine(G_BAD, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    if path.name in CORPUS_START:
        # squareness of Z to X and Y: a program that never names Z must gain Z words
        eng = StaticEngine(G_BAD + np.array([[0, 0, 0], [0, 0, 0], [700e-6, -500e-6, 0]]), [0.03, -0.02, 0.01],
                           [[-1e4] * 3, [1e4] * 3])
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    try:
        out, rep = correct_text(text, eng, setup, CorrectOptions())
    except PostprocError:
        if path.name in CORPUS_START:
            raise
        pytest.skip("refused (see the round-trip test for why)")
    if rep.moves == 0:
        pytest.skip("the program makes no move (a file of subroutine definitions)")
    if rep.expanded:
        # compare with the flat program (its lines in the order they run), so that the
        # line numbers on both sides count the same way
        from postproc.gcode.expand import expand

        text = "".join(sl.text for sl in expand(split_lines(text), path=str(path)))
    # fine sampling: the nominal polyline must follow 0.1 mm arcs to well under 1 um
    assert landing_error(text, out, eng, setup, step=0.01) <= TOL * 1.01
    if path.name in CORPUS_START:
        assert out.count("Z") > 10
        assert "Z" not in text.upper()
        assert landing_error(text, text, eng, setup, step=0.5) > 20 * TOL


@pytest.mark.parametrize("setting", ["G92 X0 Y0", "G10 L20 P1 X0 Y0", "G20 G92 X0 Y0"])
def test_offsets_set_from_the_machine_position_follow_the_correction(setting):
    """G92 and G10 L20 set an offset from where the machine is: in the corrected program
    the machine is at the corrected point there, so the words of the setting move by the
    correction, or every later absolute move lands off by it."""
    eng = StaticEngine(G_BAD, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    inch = setting.startswith("G20")
    k = 1 / 25.4 if inch else 1.0
    text = (f"G21 G90 G17 G54\nG0 X100 Y80 Z50\nG1 X120 Y90 F500\n{setting}\n"
            + "".join(f"G1 X{x * k:.5f} Y{y * k:.5f}\n" for x, y in [(10, 0), (10, 10), (-30, 20), (0, 0)])
            + "G10 L2 P1 X0 Y0 Z0\nG54 G92.1 G21\nG0 X100 Y100\nM2\n")
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)})
    out, _rep = correct_text(text, eng, setup, CorrectOptions(tolerance_mm=TOL))
    assert landing_error(text, out, eng, setup) <= TOL * 1.01
    # the setting's own words changed (the correction at the machine there is ~ 30 um)
    line = next(ln for ln in emit.split_header(out)[1].splitlines() if setting.split()[-2] in ln and "X" in ln)
    assert line != setting


def test_settings_from_the_position_stay_as_they_are_under_identity():
    from postproc.engine.identity import IdentityEngine

    text = "G21 G90 G54\nG0 X100 Y80 Z50\nG92 X0 Y0\nG1 X10 F500\nG10 L20 P1 X5\nG92.1\nM2\n"
    out, _ = correct_text(text, IdentityEngine([[-1e4] * 3, [1e4] * 3]), Setup(offsets={"G54": (0.0, 0.0, 0.0)}),
                          CorrectOptions())
    assert emit.split_header(out)[1] == text


def test_a_position_the_program_stores_is_the_corrected_one():
    """G28.1 stores where the controller is, the corrected position; a later G28 goes back
    there, and the moves after it (G91, axes left out) start from it. (A G28 that sends
    only some axes to a stored position mixes them with others: a machine position, it is
    not corrected.)"""
    eng = StaticEngine(G_BAD, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
    text = ("G21 G90 G17 G54\nG0 X100 Y80 Z50\nG1 X120 Y90 F500\nG28.1\nG1 X10 Y10\nG28\n"
            "G91 G1 X5 Y5\nX-10\nG90 G1 Y20\nG28 X50 Y20\nG1 Y30\nM2\n")
    setup = Setup(offsets={"G54": (0.0, 0.0, 0.0)})
    out, _rep = correct_text(text, eng, setup, CorrectOptions(tolerance_mm=TOL))
    assert landing_error(text, out, eng, setup) <= TOL * 1.01
