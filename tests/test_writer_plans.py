"""The planner makes every engine call of a chunk before it is written: the writer asks
for what it finds it needs (the general plan of an arc whose hint does not hold for its
ends as written, the engine's subdivision of a fitted curve), goes back to where it last
saved its state, and writes on once the planner has made it; the output and the
report are those of a writer that never stopped."""

import math

import numpy as np
import pytest
from conftest import ROOT

from postproc.calfile import load_calibration
from postproc.effects import compose
from postproc.engine.static import StaticEngine
from postproc.errors import SolverError
from postproc.gcode import emitter, engine_use, planner, writer
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

BOX = [[0] * 3, [315] * 3]


def _short_pitch_engine(pitch_mm: float = 0.6, amp_mm: float = 0.01):
    """A scale error and a lead-screw error on X whose pitch is near the planner's sample
    step, so that the arc fits follow the corrected curve more finely than its samples."""
    base = StaticEngine([[1.0002, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 0], BOX)
    return compose(base, [{"name": "periodic:X", "config": {"pitch_mm": pitch_mm},
                           "params": {"cos_mm": amp_mm, "sin_mm": 0.0}}])


SUBDIVIDED = ("G21 G90 G17\nG0 X100 Y100 Z100\nG1 X105 F500\nG2 X110 Y100 I2.5 J0\nG1 X100.3 Y103\n"
              "G3 X120 Y110 R15\nG1 Y120\nM2\n")


def _odd_step_arcs() -> str:
    """Half-turns of 0.1-0.3 mm radius (as CAM links two passes) whose corrected ends,
    rounded, leave no centre words on their bisector (an odd last step across a short
    chord): their hints fail when written, and the planner guesses so
    (``Planner._hints_failing_rounded``) unless the tests take the guess away."""
    rng = np.random.default_rng(5)
    out = ["G21 G90 G17\n", "G0 X150 Y150 Z100\n", "G1 Z90 F500\n"]
    x, y = 150.0, 150.0
    for _ in range(40):
        r = float(rng.uniform(0.1, 0.3))
        out.append(f"G3 X{x:.3f} Y{y + 2 * r:.3f} I0 J{r:.3f}\n")
        out.append(f"G1 X{x + 1:.3f} Y{y + 2 * r:.3f}\n")
        x += 1.0
        out.append(f"G2 X{x:.3f} Y{y:.3f} I0 J{-r:.3f}\n")
    out.append("M2\n")
    return "".join(out)


@pytest.fixture
def requests(monkeypatch):
    """What the writer asked the planner for, in order: ("plan", row) or ("sub", span)."""
    asked: list[tuple] = []
    provide = planner.Planner.provide

    def counted(self, need, *args):
        asked.append(("plan", need.row) if need.curve is None else ("sub", need.key[1:]))
        return provide(self, need, *args)

    monkeypatch.setattr(planner.Planner, "provide", counted)
    return asked


@pytest.fixture
def no_engine_call_while_writing(monkeypatch):
    """Fails a test in which the engine is called while a chunk is being written."""
    state = {"writing": False, "calls": 0}
    corrected = engine_use.EngineCalls.corrected
    write = writer.ChunkWriter.write

    def guarded(self, *args, **kwargs):
        assert not state["writing"], "an engine call while writing"
        state["calls"] += 1
        return corrected(self, *args, **kwargs)

    def writing(self, *args, **kwargs):
        state["writing"] = True
        try:
            return write(self, *args, **kwargs)
        finally:
            state["writing"] = False

    monkeypatch.setattr(engine_use.EngineCalls, "corrected", guarded)
    monkeypatch.setattr(writer.ChunkWriter, "write", writing)
    return state


def test_hints_that_fail_when_written_are_planned_before_writing(monkeypatch, requests,
                                                                  no_engine_call_while_writing):
    static = load_calibration(ROOT / "calibrations" / "s500_static.json").engine
    text = _odd_step_arcs()
    expected, rep0 = correct_text(text, static, Setup())
    assert rep0.arcs_split > 20  # the hints failed: the arcs were fitted from their plans
    assert requests == []  # the planner's guess made them all with the chunk's, in one engine call
    monkeypatch.setattr(planner.Planner, "_hints_failing_rounded", lambda self, arcs, budget: set())
    got, rep = correct_text(text, static, Setup())
    rows = [row for what, row in requests if what == "plan"]
    assert len(rows) > 20
    assert len(set(rows)) == len(rows)  # each asked for once: the writer goes on from where it was
    assert no_engine_call_while_writing["calls"] > 0
    assert got == expected
    assert vars(rep) == vars(rep0)


def _saves_only_at_chunk_start(monkeypatch):
    """The writer saves its state only at a chunk's start: whatever it needs, it goes back
    there and writes the chunk again."""
    save = writer.ChunkWriter._save

    def coarse(self, o, i, at=None):
        if not o.saved:
            save(self, o, i, at)

    monkeypatch.setattr(writer.ChunkWriter, "_save", coarse)


@pytest.mark.parametrize("coarse", [False, True])
def test_the_writer_goes_on_from_its_saved_state_as_if_it_never_stopped(monkeypatch, coarse):
    """Whether the writer goes back to just before the move that needed its plan or to
    the chunk's start, the text and the report's figures are the same."""
    static = load_calibration(ROOT / "calibrations" / "s500_static.json").engine
    text = _odd_step_arcs()
    expected, rep0 = correct_text(text, static, Setup())
    monkeypatch.setattr(planner.Planner, "_hints_failing_rounded", lambda self, arcs, budget: set())
    if coarse:
        _saves_only_at_chunk_start(monkeypatch)
    for chunk in (None, 7, 50):
        got, rep = correct_text(text, static, Setup(), CorrectOptions(chunk_lines=chunk))
        assert got == expected
        assert vars(rep) == vars(rep0)


def test_a_fits_subdivisions_are_made_by_the_planner_in_growing_batches(monkeypatch, requests,
                                                                      no_engine_call_while_writing):
    """One span at a curve's first request, twice as many at each next: a fit that
    needs k spans asks about log2(k) times, not k times."""
    eng = _short_pitch_engine()
    used: list[tuple[float, float]] = []
    plain = emitter.EmitterMixin.subdivision

    def recording(self, curves, s_init, unit):
        got = plain(self, curves, s_init, unit)
        used.append((float(s_init[0][0]), float(s_init[0][-1])))
        return got

    monkeypatch.setattr(emitter.EmitterMixin, "subdivision", recording)
    out, rep = correct_text(SUBDIVIDED, eng, Setup())
    subs = [r for r in requests if r[0] == "sub"]
    k = len(set(used))  # (a fit written again after a request asks again for the spans it had)
    assert k > 40  # the fits followed the curves more finely than their samples
    # three moves are fitted: at most log2(k) + 1 requests for each
    assert len(subs) <= 3 * (math.log2(k) + 1)
    assert rep.lines_inserted > 50
    # the corrected program is the same when the writer goes back to the chunk's start
    _saves_only_at_chunk_start(monkeypatch)
    again, _ = correct_text(SUBDIVIDED, eng, Setup())
    assert again == out


def _refuse(monkeypatch, spans: set[tuple[float, float]]):
    """The engine's subdivision refuses ``spans``, and any call of several spans with one of them."""
    subdivide = engine_use.EngineCalls.subdivide

    def refusing(self, curves, s_init, unit):
        if any((float(s[0]), float(s[-1])) in spans for s in s_init):
            raise SolverError("a jump in the corrected path here")
        return subdivide(self, curves, s_init, unit)

    monkeypatch.setattr(engine_use.EngineCalls, "subdivide", refusing)


def test_a_span_the_engine_refuses_is_refused_only_where_a_fit_needs_it(monkeypatch):
    eng = _short_pitch_engine()
    used: list[tuple[float, float]] = []
    all_spans: set[tuple[float, float]] = set()
    plain = emitter.EmitterMixin.subdivision
    subdivide = engine_use.EngineCalls.subdivide

    def recording(self, curves, s_init, unit):
        used.append((float(s_init[0][0]), float(s_init[0][-1])))
        return plain(self, curves, s_init, unit)

    def made(self, curves, s_init, unit):
        all_spans.update((float(s[0]), float(s[-1])) for s in s_init)
        return subdivide(self, curves, s_init, unit)

    monkeypatch.setattr(engine_use.EngineCalls, "subdivide", made)

    monkeypatch.setattr(emitter.EmitterMixin, "subdivision", recording)
    expected, _ = correct_text(SUBDIVIDED, eng, Setup())
    unused = sorted(all_spans - set(used))
    assert used
    assert unused
    with monkeypatch.context() as m:
        _refuse(m, {unused[len(unused) // 2]})
        got, _ = correct_text(SUBDIVIDED, eng, Setup())
    assert got == expected  # the batch was refused, each span subdivided alone, this one not needed
    with monkeypatch.context() as m:
        _refuse(m, {used[len(used) // 2]})
        with pytest.raises(SolverError, match="a jump"):
            correct_text(SUBDIVIDED, eng, Setup())


def test_a_run_is_written_on_from_the_arc_that_needed_its_plan(monkeypatch, requests):
    """An arc of a long run of plain lines whose hint fails when written: the writer goes
    back only to that arc, so no line of the run is written twice (going back to the
    run's start made a run of n such arcs cost n times its length)."""
    from postproc.gcode import bulk

    static = load_calibration(ROOT / "calibrations" / "s500_static.json").engine
    text = _odd_step_arcs()
    expected, _ = correct_text(text, static, Setup())
    written: list[tuple[int, int, int]] = []
    write_stretch = bulk._write_stretch

    def recorded(corrector, st, stop, *args):
        written.append((id(st.run.block), st.s, stop))
        return write_stretch(corrector, st, stop, *args)

    monkeypatch.setattr(bulk, "_write_stretch", recorded)
    monkeypatch.setattr(planner.Planner, "_hints_failing_rounded", lambda self, arcs, budget: set())
    got, _ = correct_text(text, static, Setup())
    assert got == expected
    assert len(requests) > 20
    lines = [(blk, y) for blk, s, stop in written for y in range(s, stop)]
    assert len(lines) > 50
    assert len(set(lines)) == len(lines)


def test_a_line_read_by_the_interpreter_is_written_again_only_when_it_needed_its_plan(monkeypatch, requests):
    """Lines the interpreter reads (a comment makes them so): the writer goes back to the
    start of the line whose arc needed its plan, not further."""
    static = load_calibration(ROOT / "calibrations" / "s500_static.json").engine
    text = _odd_step_arcs().replace(" I0 J", " (arc) I0 J")
    expected, _ = correct_text(text, static, Setup())
    calls: list[int] = []
    hinted = emitter.EmitterMixin.emit_hinted_arc

    def counted(self, line, mv, *args):
        calls.append(mv.lineno)
        return hinted(self, line, mv, *args)

    monkeypatch.setattr(emitter.EmitterMixin, "emit_hinted_arc", counted)
    monkeypatch.setattr(planner.Planner, "_hints_failing_rounded", lambda self, arcs, budget: set())
    got, _ = correct_text(text, static, Setup())
    assert got == expected
    assert len(requests) > 20
    arcs = text.count("\nG2 ") + text.count("\nG3 ")
    assert len(calls) == arcs + len(requests)  # each arc once, and again the ones that needed their plan
