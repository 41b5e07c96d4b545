"""Helpers shared by the test modules: paths, setups, engines, program generators and
the distances the path checks use."""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import strategies as st

from postproc.calibration.measurements import Measurements
from postproc.engine.static import StaticEngine
from postproc.errors import PostprocError
from postproc.gcode.interp import Interpreter
from postproc.gcode.path import Setup, program_path
from postproc.gcode.pipeline import CorrectOptions, correct_text
from postproc.gcode.state import PLANES
from postproc.simulate.verify import Polyline
from postproc.simulate.verify import polyline_distance as verify_polyline_distance

ROOT = Path(__file__).parents[1]
SAMPLES = ROOT / "samples"
SHARED = ROOT.parent / "shared"  # corpus and benchmark generator; tests that need them skip without
CORPUS = SHARED / "corpus"
CORPUS_EXTS = frozenset({".nc", ".ngc", ".tap", ".gcode"})
#: POSTPROC_FULL_CORPUS=1 runs the corpus tests on every program of ../shared/corpus
#: (minutes); by default they run on the representative subset of corpus_programs().
FULL_CORPUS = os.environ.get("POSTPROC_FULL_CORPUS", "") not in ("", "0")

# -- the smooth test machine of the tangential engines and its measurements --------
SIDE_MM = 315.0


#: Seed 000, Table 1 control points.
TABLE1_POINTS = np.array([
    [230, 230, 230], [110, 170, 185], [170, 125, 200], [198, 196, 140], [130, 140, 106],
    [50, 50, 50], [133, 198, 176], [80, 112, 118], [162, 168, 210], [108, 136, 168],
], dtype=float)


class TangentTestMachine:
    """Smooth test machine; ``screw`` = (amplitude mm, pitch mm) of a periodic X/Y error.

    ``scale`` multiplies every error but the periodic one.
    """

    def __init__(self, screw=(0.001, 16.0), scale: float = 2.0) -> None:
        self.screw = screw
        self.scale = scale

    def errors(self, q):
        q = np.asarray(q, dtype=float)
        x, y, z = (q[:, j] / SIDE_MM for j in range(3))
        # Linear part: offset, scale and squareness (what the static method removes).
        lin = np.array([0.045, -0.030, 0.020]) + q @ (np.array([
            [420e-6, -260e-6, 180e-6],
            [0.0, 330e-6, -240e-6],
            [0.0, 0.0, 280e-6],
        ]).T)
        # Curved axes: positioning and straightness, as smooth functions of one axis.
        curved = np.column_stack([
            0.060 * np.sin(np.pi * x) + 0.035 * y**2 - 0.030 * np.sin(1.5 * np.pi * z),
            0.050 * x**2 - 0.055 * np.sin(np.pi * y) + 0.030 * z**3,
            -0.045 * np.sin(np.pi * x) + 0.040 * y**2 - 0.040 * np.sin(np.pi * z),
        ])
        # Angular errors of X and Y acting on the lever of the axes above them.
        eps_x = np.column_stack([120e-6 * np.sin(np.pi * x), -150e-6 * x**2, 80e-6 * x])
        eps_y = np.column_stack([-130e-6 * y**2, 90e-6 * np.sin(np.pi * y), -60e-6 * y])
        lever_x = np.column_stack([np.zeros_like(x), q[:, 1], q[:, 2] + 150.0])
        lever_y = np.column_stack([np.zeros_like(x), np.zeros_like(x), q[:, 2] + 150.0])
        coupled = np.cross(eps_x, lever_x) + np.cross(eps_y, lever_y)
        amp, pitch = self.screw
        periodic = amp * np.column_stack([
            np.sin(2 * np.pi * q[:, 0] / pitch), np.sin(2 * np.pi * q[:, 1] / pitch + 1.0), np.zeros_like(x)
        ])
        eps = eps_x + eps_y + np.column_stack([np.zeros_like(x), 50e-6 * z, -40e-6 * z])
        return self.scale * (lin + curved + coupled) + periodic, self.scale * eps

    def forward(self, q, r=None, context=None):
        q = np.asarray(q, dtype=float)
        r = np.zeros_like(q) if r is None else np.broadcast_to(np.asarray(r, dtype=float), q.shape)
        rho, eps = self.errors(q)
        return q + r + rho + np.cross(eps, r)


def grid_measurements(machine, step=15.0, side=SIDE_MM, tool=(0.0, 0.0, 0.0), sigma=0.002,
                      shots=1, seed=0) -> Measurements:
    """Tracker points on a regular lattice 0..side with the given step (``shots`` per node)."""
    ax = np.arange(0.0, side + 1e-9, step)
    q = np.stack(np.meshgrid(ax, ax, ax, indexing="ij"), -1).reshape(-1, 3)
    q = np.repeat(q, shots, axis=0)
    r = np.tile(np.asarray(tool, dtype=float), (len(q), 1))
    rng = np.random.default_rng(seed)
    m = machine.forward(q, r) + rng.normal(0.0, sigma, q.shape)
    return Measurements(q=q, m=m, r=r, path="grid.csv")


def six_point_measurements(machine, side=SIDE_MM, tool=(0.0, 0.0, 0.0), sigma=0.002, seed=0) -> Measurements:
    """The seed's static set: two points per axis."""
    a = side - 15.0
    q = np.array([[15, 15, 15], [a, 15, 15], [15, 15, 15], [15, a, 15], [15, 15, 15], [15, 15, a]], float)
    r = np.tile(np.asarray(tool, dtype=float), (len(q), 1))
    rng = np.random.default_rng(seed)
    return Measurements(q=q, m=machine.forward(q, r) + rng.normal(0.0, sigma, q.shape), r=r, path="six.csv")


# -- the bulk lane against the general path: engine, setup and generated programs ---
# squareness and scale: a move on one axis moves the others, so words get added
G = np.array([[1 + 300e-6, 900e-6, -600e-6], [0.0, 1 - 200e-6, 1000e-6], [0.0, 0.0, 1 + 150e-6]])
ENGINE = StaticEngine(G, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3])
SETUP = Setup(offsets={"G54": (100.0, 80.0, 40.0)}, tool_lengths={1: 50.0})
# a real program placed in the S500's calibrated volume (as benchmarks/corpus_speed.py does)
INSIDE = Setup(offsets={"G54": (150.0, 150.0, 150.0)}, tool_lengths={t: 0.0 for t in range(100)})
MODES = {
    "bulk": {},
    "general": {"bulk_lane": False},
}


def both_lanes(text, engine, setup, **options):
    """The output (or the refusal, as ``"Type: message"``) of the bulk lane and of the
    general path, in that order."""
    outs = []
    for bulk_lane in (True, False):
        try:
            outs.append(correct_text(text, engine, setup, CorrectOptions(bulk_lane=bulk_lane, **options))[0])
        except PostprocError as exc:
            outs.append(f"{type(exc).__name__}: {exc}")
    return outs


def path_and_diff_both_ways(monkeypatch, tmp_path, text, engine, setup, step_mm=0.5):
    """The path (``program_path``) of ``text`` and diff's report of it against its
    correction, read with runs in bulk and with every line by the interpreter: asserts
    the two ways agree and returns the report."""
    from postproc.gcode import bulk
    from postproc.gcode.compare import compare_programs

    orig, corr = tmp_path / "o.ngc", tmp_path / "c.ngc"
    orig.write_text(text)
    corr.write_text(correct_text(text, engine, setup, CorrectOptions())[0])
    allows = bulk.state_allows
    paths, reports = [], []
    for use in (True, False):
        monkeypatch.setattr(bulk, "state_allows", allows if use else (lambda *a, **k: False))
        paths.append(program_path(text, setup, max_step_mm=step_mm))
        reports.append(compare_programs(str(orig), str(corr), setup).to_dict())
    a, b = paths
    assert np.array_equal(a.points_mm, b.points_mm)
    assert np.array_equal(a.lineno, b.lineno)
    assert sorted(a.context) == sorted(b.context)
    for key in a.context:
        assert np.array_equal(a.context[key], b.context[key]), key
    assert reports[0] == reports[1]
    return reports[0]


def run_all(text, *, chunk_lines=20_000, setup=SETUP, engine=ENGINE, **options):
    outs = {}
    for name, mode in MODES.items():
        opts = CorrectOptions(chunk_lines=chunk_lines, **options, **mode)
        try:
            out, rep = correct_text(text, engine, setup, opts)
            outs[name] = (out, dataclasses.asdict(rep))
        except PostprocError as exc:
            outs[name] = (str(exc), None)
    return outs


def assert_same(outs):
    ref = outs["general"]
    assert outs["bulk"][0] == ref[0]
    assert outs["bulk"][1] == ref[1]


# -- generated programs ------------------------------------------------------------------
def number(draw, lo=-200.0, hi=200.0):
    v = draw(st.floats(lo, hi, allow_nan=False))
    d = draw(st.sampled_from([0, 1, 2, 3, 4, 4, 4, 5, 6, 8]))
    text = f"{v:.{d}f}"
    style = draw(st.sampled_from(["plain", "plain", "plus", "trail", "lead"]))
    if style == "plus" and not text.startswith("-"):
        text = "+" + text
    elif style == "trail" and "." in text:
        text = text.rstrip("0")
    elif style == "lead" and text.startswith("0."):
        text = text[1:]
    elif style == "lead" and text.startswith("-0."):
        text = "-" + text[2:]
    return text


@st.composite
def plain_line(draw):
    sp = draw(st.sampled_from([" ", " ", "", "\t", "  "]))
    words = []
    if draw(st.booleans()):
        words.append(f"N{draw(st.integers(0, 99999))}")
    if draw(st.integers(0, 2)):
        words.append("G" + draw(st.sampled_from(["0", "1", "00", "01", "1", "1"])))
    feed = f"F{draw(st.sampled_from(['500', '1200.5', '80']))}" if draw(st.integers(0, 4)) == 0 else ""
    if feed and draw(st.booleans()):  # the feed before the axis words (G1 F500 X..)
        words.append(feed)
        feed = ""
    axes = draw(st.lists(st.sampled_from("XYZ"), min_size=1, max_size=3, unique=True))
    for a in "XYZ":
        if a in axes:
            words.append(a + draw(st.sampled_from(["", "", " "])) + number(draw))
    if feed:
        words.append(feed)
    if draw(st.integers(0, 9)) == 0 and len(words) > 1:  # a non-canonical order
        words[-1], words[-2] = words[-2], words[-1]
    line = draw(st.sampled_from(["", " ", "\t"])) + sp.join(words) + draw(st.sampled_from(["", "", " "]))
    return line.lower() if draw(st.integers(0, 9)) == 0 else line


@st.composite
def other_line(draw):
    return draw(st.sampled_from([
        "G2 X{a} Y{b} I5 J0", "G3 X{a} Y{b} R40", "(comment X1 Y2)", "", "G91", "G90", "G20", "G21",
        "G1 X{a} (tail comment)", "G0 Z{b} ; note", "G54", "G43 H1", "G0 G43 H1 Z{b}", "G1 G43 H0 X{a} Y{b}", "G49", "M3 S1000", "/G1 X{a}",
        "G92 X{a}", "G92.1", "G17", "G18 G2 X{a} Z{b} I3 K3", "G1 F300", "N5", "%", "M30",
        "S1200 M3", "M9", "N20 (note)", "  ", "(MSG, hello)", "M8 (coolant)", "F250", "N30 F1200.5", " f80 ",
        "A5 F300", "G43 H1 F300", "F300 G1 X{a}", "G1 F300 X{a} F200", "F-5",
    ])).format(a=draw(st.integers(-150, 150)), b=draw(st.integers(-150, 150)))


# -- how far a corrected program lands from the nominal path -----------------------
def assert_offsets_cut_the_line(line: str, at: list[int], has: list[bool], values: list[float], late: bool) -> None:
    """A plain line's offsets (plainscan.Pieces.at, one line's: head end, then each of X,
    Y, Z, I, J's number's start and end) against the lexer's words: in order within the
    line; a named word's number where the lexer has it (its text, its value), the
    head's words before the first axis word; and the run writer (runwords.join_rows)
    putting new numbers in at them gives the line with those numbers, every other byte
    as it was."""
    from postproc.gcode import lexer, runwords

    body = line.rstrip("\n")
    words = [t for t in lexer.lex(body) if t.kind == lexer.WORD]
    span = {t.letter.upper(): (t.col - 1 + t.number_offset, t.col - 1 + t.number_offset + len(t.number_text))
            for t in words}
    assert all(a <= b for a, b in zip(at, at[1:], strict=False))
    assert at[-1] <= len(body)
    for k, letter in enumerate("XYZIJ"):
        if late and letter in "XY":
            continue  # after Z: cut from its run, never rewritten by the run writer
        a, b = at[1 + 2 * k], at[2 + 2 * k]
        assert has[k] == (letter in span) == (b > a)
        if has[k]:
            assert (a, b) == span[letter]
            assert values[k] == float(body[a:b])
    head = body[:at[0]]
    assert all(t.letter.upper() in "NGHF" for t in lexer.lex(head) if t.kind == lexer.WORD)
    if late:
        return
    # new numbers put in at the offsets: the line with those numbers, nothing else changed
    new = {letter: f"<{letter}>" for k, letter in enumerate("XYZIJ") if has[k]}
    expected, p = [], 0
    for a, b, letter in sorted((*span[letter], letter) for letter in new):
        expected += [line[p:a], new[letter]]
        p = b
    expected.append(line[p:])
    cols = [[x] for x in at]
    got = runwords.join_rows([line], (0, 1), cols, [[new.get(c, "")] for c in "XYZ"], [""],
                             ([new.get("I", "")], [new.get("J", "")]))
    assert got == "".join(expected)
    assert runwords.join_rows([line], (0, 1), cols, [[""], [""], [""]], [""], ([""], [""])) == line


def polyline_distance(points: np.ndarray, poly: np.ndarray, step: float = 0.05) -> np.ndarray:
    """Distance from each point to the polyline through ``poly`` (exact; the package's
    own, indexed by pieces of at most ``step``)."""
    return verify_polyline_distance(points, poly, piece_mm=step)


def first_known_line(text: str, setup: Setup) -> int:
    """First line after which every axis has been positioned (before it, the machine's
    position is unknown and so is the path); programs needing expansion read expanded."""
    from postproc.gcode.options import CorrectOptions
    from postproc.gcode.pathread import read_program
    from postproc.gcode.reader import LineReader

    class FirstKnown(LineReader):
        found: int | None = None

        def queue(self, line, mv, lineno) -> None:
            it = self.interp
            if self.found is None and (mv is not None or it.cycle_move is not None) \
                    and not any(math.isnan(v) for v in it.state.pos):
                self.found = lineno

        def queue_run(self, run) -> None:  # a run starts where every axis is known
            if self.found is None:
                self.found = run.lineno

    rd = read_program(text, setup, lambda interp, path: FirstKnown(interp, CorrectOptions(), path))
    return rd.found if rd.found is not None else 10**9


def landing_error(original: str, corrected: str, engine, setup: Setup, step: float = 0.05) -> float:
    """Largest distance between the actual path of ``corrected`` and the nominal path
    of ``original``, both ways (feed moves and rapid end points, from the first point
    where the machine position is known). Sampled as finely as asked, beyond the bound
    ``verify`` puts on its own sampling (a measurement of the tests, not a user's run)."""
    from postproc.gcode.path import sample_program

    def program_path(source, setup, max_step_mm):
        return sample_program(source, setup, step_mm=max_step_mm, max_samples=10**8)

    nom = program_path(original, setup, max_step_mm=step)
    nominal = nom.points_mm[nom.lineno >= first_known_line(original, setup)]
    pp = program_path(corrected, setup, max_step_mm=step)
    keep = pp.lineno >= first_known_line(corrected, setup)
    actual = engine.forward(pp.points_mm - pp.tool_mm, pp.tool_mm, pp.context)[keep]
    there = polyline_distance(actual, nominal).max()
    back = polyline_distance(nominal, actual).max()
    return float(max(there, back))


# -- the setup corpus programs are corrected with ----------------------------------
# every work offset and tool length a corpus program might name, so that the run
# goes as far as the program's own constructs allow
ALL_OFFSETS = {n: (0.0, 0.0, 0.0) for n in
               ["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"]}
ALL_TOOLS = {t: 50.0 + t for t in range(100)}
BIG = [[-1e5] * 3, [1e5] * 3]


# 2-D programs that never name Z: corrected with the machine's Z given by --start
# (docs/gcode.md, "Start position"); without it they are refused
CORPUS_START = {"Star_Trek.tap": {"Z": 150.0}, "plug6a.tap": {"Z": 150.0}}


def corpus_setup(path: Path) -> Setup:
    """The setup a corpus program is corrected with (every offset and tool, its start)."""
    return Setup(offsets=ALL_OFFSETS, tool_lengths=ALL_TOOLS, start=CORPUS_START.get(path.name, {}))


# -- emitted arcs and the corrected ideal path -------------------------------------
PARAMETRIC = ROOT / "calibrations" / "s500_parametric.json"
TOL = 0.001
STEP = 0.02  # sampling of both paths (mm): the polyline error of a 0.5 mm arc is 0.1 nm


def emitted_arcs(text: str, setup: Setup):
    """(unit, start radius, end radius) of every arc in ``text``, read by the interpreter."""
    interp = Interpreter(setup, None)
    out = []
    for lineno, line in enumerate(text.splitlines(keepends=True), start=1):
        mv = interp.feed_line(lineno, line)
        if mv is None or mv.arc is None:
            continue
        (a1, a2, _an), _ = PLANES[mv.arc.plane]
        c = mv.arc.center
        r0 = math.hypot(mv.q0[a1] - c[a1], mv.q0[a2] - c[a2])
        r1 = math.hypot(mv.q1[a1] - c[a1], mv.q1[a2] - c[a2])
        out.append((mv.unit, r0, r1, lineno))
    return out


def ideal_vs_emitted(original: str, corrected: str, engine, setup: Setup, dialect: str = "generic") -> float:
    """Largest distance, both ways over feed moves, between the corrected ideal path (the
    engine's correction of the original's dense samples) and the emitted path."""
    nom = program_path(original, setup, max_step_mm=STEP, dialect=dialect)
    q = nom.points_mm - nom.tool_mm
    ideal = q + np.asarray(engine.correction(nom.points_mm, nom.tool_mm, nom.context).q)
    out = program_path(corrected, setup, max_step_mm=STEP, dialect=dialect)
    emitted = out.points_mm - out.tool_mm
    feed_i, feed_o = ~nom.rapid, ~out.rapid
    there, _ = Polyline(ideal, feed_i[1:]).nearest(emitted[feed_o])
    back, _ = Polyline(emitted, feed_o[1:]).nearest(ideal[feed_i])
    return float(max(there.max(), back.max()))


# -- the corpus programs a test runs -----------------------------------------------
_CODE = re.compile(rb"([GM]) ?0*(\d+(?:\.\d)?)")
_LOWER = re.compile(rb"[gxyz] ?-?[.\d]")
_R_WORD = re.compile(rb"[^A-Z(]R ?[-+.\d]")
_O_WORD = re.compile(rb"O ?(?:<[^>\n]*>|\d+) ?(SUB|ENDSUB|CALL|RETURN|DO|WHILE|ENDWHILE|IF|ELSEIF|ELSE|ENDIF|"
                     rb"REPEAT|ENDREPEAT|BREAK|CONTINUE)")
_OPERATOR = re.compile(rb"(ATAN|ASIN|ACOS|SIN|COS|TAN|SQRT|ABS|FIX|FUP|ROUND|EXISTS|LN|EXP) ?\[|"
                       rb"[^A-Z](MOD|EQ|NE|GT|GE|LT|LE|AND|OR|XOR)[^A-Z]")
#: constructs are read from each program's first bytes (the whole of all but the largest)
_SCAN_BYTES = 1 << 17
#: program lengths that span several chunks of the pipeline (SEGMENTED_CHUNK_LINES,
#: DEFAULT_CHUNK_LINES): a subset keeps a program over each that the test allows
_CHUNK_LINES = (2_000, 20_000)


@functools.cache
def program_features(path: Path) -> tuple[frozenset[str], int, int]:
    """(the constructs a program names, its lines, its bytes)."""
    raw = path.read_bytes()
    head = raw[:_SCAN_BYTES]
    upper = head.upper()
    lines = raw.count(b"\n")
    feats = {f"source {path.parent.name}", f"suffix {path.suffix.lower()}"}
    feats.update((c + n).decode() for c, n in _CODE.findall(upper))
    feats.update(f"over {n} lines" for n in _CHUNK_LINES if lines > n)
    if b"#" in head:  # O-word kinds and expression operators
        feats.update(f"O-word {k.decode()}" for k in _O_WORD.findall(upper))
        feats.update(f"operator {(a or b).decode()}" for a, b in _OPERATOR.findall(upper))
    markers = {
        "parameter": b"#" in head, "named parameter": b"#<" in head, "O-word": upper.startswith(b"O") or b"\nO" in upper,
        "expression": b"[" in head, "R word": _R_WORD.search(upper) is not None,
        "CRLF": b"\r\n" in head, "non-ASCII": not raw.isascii(),
        "lower case": _LOWER.search(head) is not None, "; comment": b";" in head,
        "% line": head.startswith(b"%") or b"\n%" in head,
    }
    feats.update(name for name, present in markers.items() if present)
    return frozenset(feats), lines, len(raw)


@functools.lru_cache(maxsize=1)
def corpus_files(sources: tuple[str, ...] | None = None) -> list[Path]:
    """Every program file of the corpus (by suffix; empty without ../shared/corpus),
    sorted; with ``sources``, those of each of these folders in turn."""
    if not CORPUS.is_dir():
        return []
    roots = [CORPUS] if sources is None else [CORPUS / s for s in sources]
    return [p for root in roots for p in sorted(root.rglob("*"))
            if p.suffix.lower() in CORPUS_EXTS and p.is_file()]


def _corpus_index() -> dict[Path, tuple[frozenset[str], int, int]]:
    """Every corpus program (by suffix) with its :func:`program_features`."""
    return {p: program_features(p) for p in corpus_files()}


def representative(paths: list[Path], every_below: int = 0) -> list[Path]:
    """A deterministic subset of ``paths`` that names every construct they name at least
    once: each source folder, file suffix, G and M code, parameters (numbered, named),
    O-words (each kind), expressions (each function and operator), R words, CRLF, non-ASCII bytes, lower case, ; comments, % lines, and a length over each
    chunk size; with the programs that need a start position (CORPUS_START) and every
    program of fewer than ``every_below`` lines. Chosen greedily, most new constructs per
    line first, so that short programs are preferred."""
    left = {p: program_features(p) for p in paths}
    chosen = [p for p in paths if p.name in CORPUS_START or left[p][1] < every_below]
    covered: set[str] = set().union(*(left.pop(p)[0] for p in chosen))
    wanted: set[str] = covered.union(*(f for f, _, _ in left.values()))
    while covered != wanted:
        best = max(left, key=lambda p: (len(left[p][0] - covered) / (left[p][1] + 50), -left[p][1], str(p)))
        chosen.append(best)
        covered |= left.pop(best)[0]
    return sorted(chosen)


def corpus_programs(*, max_lines: int | None = None, max_bytes: int | None = None,
                    keep=None, every_below: int = 0) -> list[Path]:
    """The corpus programs a test runs (empty without ../shared/corpus): those within
    ``max_lines`` / ``max_bytes`` for which ``keep(path)`` holds; all of them with
    POSTPROC_FULL_CORPUS=1, else their :func:`representative` subset (which keeps every
    one of fewer than ``every_below`` lines)."""
    paths = [p for p, (_, lines, size) in _corpus_index().items()
             if (max_lines is None or lines <= max_lines) and (max_bytes is None or size <= max_bytes)
             and (keep is None or keep(p))]
    return paths if FULL_CORPUS else representative(paths, every_below)


@pytest.fixture
def planned_tables(monkeypatch):
    """The move tables the planner is given while a test corrects, in order, as given."""
    from postproc.gcode import planner

    seen = []
    plan = planner.Planner.plan

    def spy(self, tab):
        seen.append(tab)
        return plan(self, tab)

    monkeypatch.setattr(planner.Planner, "plan", spy)
    return seen


def bisector_cases(rng, n: int):
    """Arcs of radius 1 um to 100 m sampled with noise, the ends rounded to 4 decimals, for
    the centre fit on the bisector: ``(S2, E2, P2, c0)`` arrays (P2 (k, 2) the samples,
    c0 a first guess near the centre); some with S2 == E2 (no bisector), a sample on the
    chord's middle, a nan."""
    for i in range(n):
        R = 10.0 ** rng.uniform(-3, 5)
        c = rng.uniform(-300, 300, 2)
        th = np.sort(rng.uniform(0, rng.uniform(1e-4, 6), int(rng.integers(2, 60))))
        P2 = c + R * np.c_[np.cos(th), np.sin(th)] + rng.normal(0, 10.0 ** rng.uniform(-9, -1), (len(th), 2))
        S2, E2 = P2[0].round(4), P2[-1].round(4)
        if i % 13 == 0:
            E2 = S2.copy()
        if i % 17 == 0:
            P2[len(P2) // 2] = 0.5 * (S2 + E2)
        if i % 19 == 0:
            P2[0] = np.nan
        c0 = c + rng.normal(0, 10.0 ** rng.uniform(-6, 0), 2)
        yield S2, E2, P2, c0
