"""Arc lines without their motion word (``X.. Y.. I.. J..`` or ``X.. Y.. R..`` under a
modal G2/G3, as FreeCAD, Fusion 360 and CAMotics write them) are read in bulk with the
plain lines around them: the output, the refusals, the path and diff's report are the
general path's, byte for byte. A line whose words do not fit the modal motion (centre
words under G1, none under G2) ends the run, and the interpreter reads or refuses it."""

import math
from pathlib import Path

import numpy as np
import pytest
from conftest import ENGINE, INSIDE, SETUP, both_lanes, path_and_diff_both_ways

from postproc.calfile import load_calibration
from postproc.gcode import bulk, emit
from postproc.gcode.moves import Kind
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.state import ARC_CW, LINE

ROOT = Path(__file__).parents[1]
REAL = ROOT.parent / "shared" / "corpus" / "real"


def _curved():
    return load_calibration(ROOT / "calibrations" / "s500_parametric.json").engine


def _both(text, engine=None, setup=SETUP, **options):
    """The output (or the refusal) of the bulk lane and of the general path."""
    return both_lanes(text, engine or ENGINE, setup, **options)


def _modal_program(rng, n, r_form=False, scale=1.0, big=0.0):
    """Passes of arcs both ways, each direction named once and then modal, with straight
    moves between (named G1, then modal too), some helical, some with a feed; every
    other arc ``big`` times larger where ``big`` is given."""
    out = ["G21 G90 G17\n", "G0 X10 Y10 Z5\n", "G1 Z-1 F300\n"]
    x, y, z = 10.0, 10.0, -1.0
    for k in range(n):
        if k % 6 == 0:
            x, y = round(x + rng.uniform(-2, 2) * scale, 3), round(y + rng.uniform(-2, 2) * scale, 3)
            out.append(f"G1 X{x:.3f} Y{y:.3f}\n")
            x, y = round(x + rng.uniform(-2, 2) * scale, 3), round(y + rng.uniform(-2, 2) * scale, 3)
            out.append(f"X{x:.3f} Y{y:.3f}\n")
        r = rng.uniform(1.0, 6.0) * scale * (big if big and k % 2 else 1.0)
        a0 = rng.uniform(0, 2 * np.pi)
        cx, cy = x - r * np.cos(a0), y - r * np.sin(a0)
        a1 = a0 + rng.uniform(-2.5, 2.5)
        ex, ey = round(cx + r * np.cos(a1), 4), round(cy + r * np.sin(a1), 4)
        head = f"G{2 + (k // 3) % 2} " if k % 3 == 0 else ""  # a direction named, then modal
        dz = f" Z{z - 0.01:.3f}" if k % 5 == 2 else ""
        f = " F250." if k % 4 == 1 else ""
        if r_form:
            rr = float(np.hypot(ex - cx, ey - cy))
            rad = f" R{rr:.4f}" if abs(a1 - a0) < np.pi else f" R-{rr:.4f}"
            out.append(f"{head}X{ex:.4f} Y{ey:.4f}{dz}{rad}{f}\n")
        else:
            out.append(f"{head}X{ex:.4f} Y{ey:.4f}{dz} I{cx - x:.4f} J{cy - y:.4f}{f}\n")
        x, y = ex, ey
        z = z - 0.01 if dz else z
        if k % 6 == 5:
            out.append("G1 F300\n")  # the modal motion back to G1 with nothing else
    out.append("M2\n")
    return "".join(out)


@pytest.mark.parametrize("r_form", [False, True])
@pytest.mark.parametrize("seed", range(3))
def test_modal_arcs_in_bulk_give_the_general_paths_output(seed, r_form):
    text = _modal_program(np.random.default_rng(seed), 60, r_form)
    a, b = _both(text)
    assert a == b
    assert "Error" not in a


@pytest.mark.parametrize("r_form", [False, True])
def test_modal_arcs_split_by_a_curved_calibration_get_their_motion_word_back(r_form):
    # every other arc too large for one exact arc to follow: it is written as several
    # pieces (or lines), and the small modal arc line after it, kept in its run, needs its
    # G2/G3 again
    text = _modal_program(np.random.default_rng(5), 24, r_form, scale=0.2, big=100.0)
    a, b = _both(text, _curved(), INSIDE, extrapolate="linear")
    assert a == b
    assert "Error" not in a
    assert a.count("G2") + a.count("G3") > text.count("G2") + text.count("G3")


def test_modal_arc_lines_are_read_in_runs(planned_tables):
    text = _modal_program(np.random.default_rng(1), 30)
    correct_text(text, ENGINE, SETUP, CorrectOptions())
    (tab,) = planned_tables
    arcs = np.flatnonzero((tab.kind == Kind.ARC_CW) | (tab.kind == Kind.ARC_CCW))
    assert len(arcs) == 30
    in_runs = {i for r in tab.runs for i in range(r.trow, r.trow + len(r))}
    assert set(arcs.tolist()) <= in_runs  # none read line by line
    # the direction of a modal arc is the last named one's
    lines = text.splitlines()
    assert all(ln.startswith(("G2", "G3", "X", "G1", "G0", "M2", "G21")) for ln in lines)
    want, cur = [], None
    for ln in lines:
        if ln.startswith(("G2", "G3")):
            cur = Kind.ARC_CW if ln.startswith("G2") else Kind.ARC_CCW
        elif ln.startswith("G1"):
            cur = Kind.FEED
        if " I" in ln:
            want.append(cur)
    assert tab.kind[arcs].tolist() == want


@pytest.mark.parametrize(("line", "message"), [
    ("X20 Y10 I5 J0", "4:9: I word on a straight move"),  # centre words under G1: the interpreter's
    ("X20 Y10 R5", "4:9: R word on a straight move"),
])
def test_arc_shaped_lines_under_a_straight_motion_are_the_interpreters(line, message):
    text = f"G21 G90 G17\nG0 X10 Y10 Z5\nG1 X10 F200\n{line}\nG1 X25\nM2\n"
    a, b = _both(text)
    assert a == b
    assert message in a
    blk = bulk.scan(text.splitlines(True))
    assert blk is not None
    assert blk.motion_end(2, 5, None) == 3  # after G1 a run ends before it
    assert blk.motion_end(3, 5, LINE) == 3  # and cannot start there under G1
    assert blk.motion_end(3, 5, ARC_CW) == 5  # under G2 it would take it


@pytest.mark.parametrize("line", ["X25 Y12", "Z4", "X25 Y12 F100"])
def test_straight_shaped_lines_under_a_modal_arc_end_the_run(line):
    # under G2 a line without centre words is an arc with none: the interpreter refuses it
    text = f"G21 G90 G17\nG0 X10 Y10 Z5\nG1 X10 F200\nG2 X20 Y10 I5 J0\n{line}\nG1 X25\nM2\n"
    a, b = _both(text)
    assert a == b
    assert "5:1: arc without centre (I/J/K) or radius (R)" in a


def test_a_run_starting_under_a_modal_arc_takes_its_arc_lines(planned_tables):
    # chunks of 4 lines after the first: the second chunk's run starts under the modal G2
    text = "G21 G90 G17\nG0 X10 Y10 Z5\nG1 X10 F200\nG2 X20 Y10 I5 J0\nX10 Y10 I-5 J0\nX20 Y10 R5\nG1 X25\nM2\n"
    outs = []
    for chunk in (4, 20_000):
        outs.append(correct_text(text, ENGINE, SETUP, CorrectOptions(chunk_lines=chunk))[0])
    assert outs[0] == outs[1] == _both(text)[1]
    first, second = planned_tables[:2]
    assert [(r.lineno, len(r)) for r in first.runs] == [(3, 3)]  # G1, G2 and the modal I/J arc
    assert first.kind.tolist() == [Kind.RAPID, Kind.FEED, Kind.ARC_CW, Kind.ARC_CW]
    assert [(r.lineno, len(r)) for r in second.runs] == [(6, 2)]  # the modal R arc, then G1
    assert second.kind.tolist() == [Kind.ARC_CW, Kind.FEED]


def test_modal_arc_path_and_diff_are_the_general_paths(monkeypatch, tmp_path):
    text = _modal_program(np.random.default_rng(3), 50)
    report = path_and_diff_both_ways(monkeypatch, tmp_path, text, ENGINE, SETUP, step_mm=0.2)
    assert report["moves_moved"] > 50


@pytest.mark.skipif(not REAL.is_dir(), reason="needs ../shared/corpus")
@pytest.mark.parametrize("name", [
    "freecad_sergey/MyCNCTable________________Y_2(_).tap",  # modal R arcs
    "fusion_ledfloor/cad__nc__1108_wall_better_m4_m6_holes.nc",  # modal I/J arcs, helical
    "camotics/examples__botomata_bottom__botomata_bottom.nc",
])
def test_real_programs_with_modal_arcs_agree(name):
    lines = (REAL / name).read_text(errors="surrogateescape").splitlines(True)[:1500]
    a, b = _both("".join(lines), setup=INSIDE, extrapolate="linear")
    assert a == b


def test_a_modal_arc_after_one_written_as_lines_gets_its_motion_word(monkeypatch):
    # Pretend the general emitter writes every R arc as straight lines (the controller is
    # then in G1), in both lanes alike: the modal I/J arc after one, which the bulk lane
    # keeps in its run, must get its G2/G3 back, as the general path gives it.
    from postproc.gcode.emitter import EmitterMixin

    for name in ("emit_move", "emit_hinted_arc"):
        orig = getattr(EmitterMixin, name)

        def as_lines(self, line, mv, *args, _orig=orig):
            _orig(self, line, mv, *args)
            if mv.arc is not None and mv.arc.r_idx >= 0:
                self.emitted_motion = LINE

        monkeypatch.setattr(EmitterMixin, name, as_lines)
    # quarter circles about (15, 10), which one exact arc follows: the I/J arcs stay in runs
    text = ("G21 G90 G17\nG0 X10 Y10 Z5\nG1 X10 F200\nG2 X15 Y15 R5\nX20 Y10 I0 J-5\nX15 Y5 I-5 J0\n"
            "X10 Y10 R5\n(note)\nX15 Y15 I5 J0\nG3 X10 Y10 R5\nX15 Y5 I5 J0\nG1 X25\nM2\n")
    a, b = _both(text)
    assert a == b
    lines = emit.split_header(a)[1].splitlines()
    # each I/J arc right after an R arc names its motion again; the one after another does not
    assert [ln.split(" ")[0][:2] for ln in lines if " I" in ln] == ["G2", "X1", "G2", "G3"]


# -- an arc handed to the general emitter in the middle of a stretch ---------------------
def _arc_chain(n: int = 10) -> tuple[str, int]:
    """A run of clockwise arcs around (0, 0), radius 20, 30 degrees each: the first names
    G2, the others are modal; and the line of the fifth."""
    lines = ["G21 G90 G17 G94", "G0 X20 Y0 Z5", "G1 Z0 F200"]
    x, y = 20.0, 0.0
    for k in range(1, n + 1):
        a = -math.radians(30 * k)
        nx, ny = round(20 * math.cos(a), 4), round(20 * math.sin(a), 4)
        lines.append(f"{'G2 ' if k == 1 else ''}X{nx:.4f} Y{ny:.4f} I{-x:.4f} J{-y:.4f}")
        x, y = nx, ny
    lines += ["G0 Z5", "M30"]
    return "\n".join(lines) + "\n", 3 + 5


def test_an_arc_whose_hint_fails_where_written_mid_stretch_and_the_modal_arc_after_it(monkeypatch):
    # the planner expected the arc's hint to hold (no edge: the stretch runs on past it),
    # but it fails for the ends as written; the run writer hands it to the general
    # emitter (bulk._general_row), whose fit here writes it as lines (G1); the modal arc
    # line after it then needs its G2 again (bulk._motion_row hands it over too). The
    # general path, told the same, writes the same bytes.
    from postproc.gcode import arcfit, vplan

    text, chosen = _arc_chain()
    arc_words, spec, exact_arc = bulk._arc_words, vplan.ArcHint.spec, arcfit.MoveFit._exact_arc

    def failing_words(corrector, run, hints, y, *rest):
        return None if run.line(y - run.a) == chosen else arc_words(corrector, run, hints, y, *rest)

    def failing_spec(self, mv, *rest):
        return None if mv.lineno == chosen else spec(self, mv, *rest)

    def no_arc(self, *args):
        return None if self.mv.lineno == chosen else exact_arc(self, *args)

    monkeypatch.setattr(bulk, "_arc_words", failing_words)
    monkeypatch.setattr(vplan.ArcHint, "spec", failing_spec)
    monkeypatch.setattr(arcfit.MoveFit, "_exact_arc", no_arc)
    handed: list[str] = []
    general_row, motion_row = bulk._general_row, bulk._motion_row

    def spy_general(corrector, run, T, write, hints, y, mark):
        handed.append(f"general {run.line(y - run.a)}")
        return general_row(corrector, run, T, write, hints, y, mark)

    def spy_motion(corrector, run, T, write, hints, s, mark):
        before = corrector.emitted_motion
        got = motion_row(corrector, run, T, write, hints, s, mark)
        if got != s:
            handed.append(f"motion {run.line(s - run.a)} after {before}")
        return got

    monkeypatch.setattr(bulk, "_general_row", spy_general)
    monkeypatch.setattr(bulk, "_motion_row", spy_motion)
    a, b = both_lanes(text, ENGINE, SETUP)
    assert a == b
    # the chosen arc by the general emitter mid-stretch, then the modal arc after it,
    # which the controller would read as G1, handed over to be written with its G2
    # (the chosen arc is handed over again each time the writer goes back for the plan
    # or the subdivisions its fit asks for; the motion row hands its arc to the general
    # row, which is told first)
    steps = [h for k, h in enumerate(handed) if not k or h != handed[k - 1]]
    assert steps == [f"general {chosen}", f"general {chosen + 1}", f"motion {chosen + 1} after {LINE}"]
    out = a.splitlines()
    first = next(i for i, ln in enumerate(out) if ln.startswith("G2 "))
    assert out[first + 4].startswith("G1 ")  # the chosen arc, written as lines
    after = next(ln for ln in out[first + 4:] if not ln.startswith(("G1 ", "X", "Y")))
    assert after.startswith("G2 ")  # the next arc names its motion again
    assert sum(ln.startswith("G2 ") for ln in out) == 2
