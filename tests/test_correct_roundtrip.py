"""Identity calibration: every program comes out byte-identical apart from the header,
or fails with a PostprocError naming its place (never a traceback)."""

from pathlib import Path

import pytest
from conftest import ALL_OFFSETS, ALL_TOOLS, BIG, CORPUS_START, corpus_programs, corpus_setup

from postproc.engine.identity import IdentityEngine
from postproc.errors import PostprocError
from postproc.gcode import emit
from postproc.gcode.path import Setup
from postproc.gcode.pipeline import CorrectOptions, correct_text

ROOT = Path(__file__).parents[1]
CORPUS = Path(__file__).parents[2] / "shared" / "corpus"
EXTS = {".nc", ".ngc", ".tap", ".gcode"}
# Every corpus program shorter than this runs (the refusals are found among them: each
# kind of refusal the corpus gives has a program this short); of the longer ones, a
# subset naming every construct, source and suffix they name. All of them with
# POSTPROC_FULL_CORPUS=1 (conftest.corpus_programs).
EVERY_BELOW_LINES = 2_000


def _files():
    files = sorted(p for p in (ROOT / "samples").rglob("*") if p.suffix.lower() in EXTS)
    return files + corpus_programs(every_below=EVERY_BELOW_LINES)


def strip_header(text: str) -> str:
    lines = text.splitlines(keepends=True)
    return "".join(ln for ln in lines if not emit.is_header(ln))


@pytest.mark.parametrize("path", _files(), ids=lambda p: f"{p.parent.name}/{p.name}")
def test_identity_roundtrip_is_byte_identical_or_a_clear_error(path):
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    setup = corpus_setup(path)
    err = None
    try:
        out, report = correct_text(text, IdentityEngine(BIG), setup, CorrectOptions(),
                                   path=str(path), calibration_name="identity", calibration_sha256="0" * 64)
    except PostprocError as exc:
        err = exc
    if err is not None:
        assert err.path == str(path)
        assert err.lineno is not None
        assert err.message
        return
    assert report.lines_inserted == 0
    assert report.words_changed == 0
    if report.expanded:
        # subprograms, loops and parameters written out: the flat program (checked against
        # LinuxCNC's rs274 in test_gcode_expand*.py) is what the identity leaves unchanged
        return
    assert strip_header(out) == text


def test_the_corpus_is_mostly_corrected_not_refused():
    if not CORPUS.is_dir():
        pytest.skip("no shared corpus")
    ok, refused = [], []
    for path in corpus_programs(every_below=EVERY_BELOW_LINES):
        text = path.read_bytes().decode("utf-8", errors="surrogateescape")
        try:
            correct_text(text, IdentityEngine(BIG), corpus_setup(path))
            ok.append(path.name)
        except PostprocError as exc:
            refused.append((path.name, exc.message))
    # refusals name a construct postproc does not correct, or a defect of the file
    known = ("macro", "O-word", "parameter", "expression", "canned cycle", "cutter radius compensation", "polar",
             "never positioned", "is not G-code", "arc end radius", "arc without end point", "arc without centre",
             # subroutine files the corpus does not hold, and a sub without its endsub
             "subroutine o<", "has no matching",
             # G41/G42 with no cutter radius given (corpus_setup gives none), LinuxCNC's D rule
             "offsets by the radius of", "requires D word to be a whole number",
             # read in the generic dialect: nested comments (Fanuc style) and G53 in G91 are
             # LinuxCNC errors; positions a program never sets
             "unexpected character ')'", "G53 is not allowed in G91", "unknown position", "unknown start position")
    assert all(any(k in msg for k in known) for _, msg in refused), refused
    assert len(ok) >= 10, refused
    # the programs that need a start position are corrected once it is given
    assert set(CORPUS_START) <= set(ok)
    for name in CORPUS_START:
        path = next(CORPUS.rglob(name))
        text = path.read_bytes().decode("utf-8", errors="surrogateescape")
        with pytest.raises(PostprocError, match="never positioned") as err:
            correct_text(text, IdentityEngine(BIG), Setup(offsets=ALL_OFFSETS, tool_lengths=ALL_TOOLS))
        assert "--start" in err.value.hint


def test_comments_in_any_encoding_are_copied_byte_for_byte(tmp_path):
    from postproc.gcode.pipeline import correct_file

    raw = ("%\r\n(Карман 60x40, фреза D8)\r\nG21 G90\r\nG0 X10 Y10 Z10 ; подвод\r\nG1 X20 F300\r\n%\r\n")
    for encoding in ("cp1251", "utf-8"):
        src = tmp_path / f"prog_{encoding}.nc"
        src.write_bytes(raw.encode(encoding))
        out = tmp_path / f"out_{encoding}.nc"
        correct_file(src, out, IdentityEngine(BIG), Setup())
        got = out.read_bytes().split(b"\r\n")
        n = sum(emit.is_header(ln.decode("ascii", errors="replace")) for ln in got)
        assert emit.is_header_start(got[1].decode("ascii"))
        assert b"\r\n".join(got[:1] + got[1 + n:]) == raw.encode(encoding)
