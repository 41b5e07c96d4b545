"""The block reader (``postproc.fileio.read_blocks`` and ``Lines``): the lines
``read_lines`` gives, with the same endings, refused at the same line and after a bounded
read, in the blocks ``list(islice(lines, n))`` makes; and ``correct`` given a program's
lines a block at a time writes, counts and reports what it does given them one at a time."""

from __future__ import annotations

import io
from contextlib import nullcontext
from itertools import islice

import pytest
from conftest import ENGINE, SAMPLES, SETUP
from hypothesis import given, settings
from hypothesis import strategies as st

from postproc.errors import PostprocError
from postproc.fileio import Lines, read_blocks, read_lines
from postproc.gcode.pipeline import CorrectOptions, Corrector, correct_file
from postproc.gcode.source import iter_source_lines
from postproc.limits import Limits, ResourceLimitError

# pieces of a file: every line end readline knows ("\r", "\n", "\r\n") and those it does
# not (form feed, vertical tab, file separator, NEL, LINE SEPARATOR), bytes that are not
# UTF-8 (read through surrogateescape: a lone byte, a cut sequence, an encoded surrogate),
# a byte-order mark, NUL, and text
PIECES = [b"\r", b"\n", b"\r\n", b"\r\r\n", b"\n\r", b"G1 X1", b"a", b" ", b"\x00", b"\x0c", b"\x0b", b"\x1c",
          b"\xc2\x85", b"\xe2\x80\xa8", b"\xff", b"\xe2\x80", b"\xed\xa0\x80", b"\xef\xbb\xbf", b"\xc3\xa9"]


def _open(data: bytes, chunk: int) -> io.TextIOWrapper:
    """``data`` opened as a program is (:func:`postproc.gcode.source.open_source`), its
    bytes decoded ``chunk`` at a time (a multi-byte character cut between two)."""
    fh = io.TextIOWrapper(io.BytesIO(data), encoding="utf-8", errors="surrogateescape", newline="")
    fh._CHUNK_SIZE = chunk  # type: ignore[attr-defined]
    return fh


def _blocks(take, n: int) -> tuple[list[list[str]], PostprocError | None]:
    """The blocks ``take(n)`` gives to the end, and the error that ended them (None)."""
    out: list[list[str]] = []
    try:
        while block := take(n):
            out.append(block)
    except PostprocError as exc:
        return out, exc
    return out, None


def _place(err: PostprocError | None) -> tuple | None:
    return None if err is None else (err.path, err.lineno, err.col, err.message, err.hint)


def _all(lines) -> tuple[list[str], PostprocError | None]:
    """Every line of ``lines`` (an iterator of lines or of lists of them) before its error, and the error."""
    out: list[str] = []
    try:
        for x in lines:
            if isinstance(x, list):
                assert x  # no empty list
                out += x
            else:
                out.append(x)
    except PostprocError as exc:
        return out, exc
    return out, None


@given(st.lists(st.sampled_from(PIECES), max_size=80), st.integers(1, 40), st.integers(1, 50), st.integers(1, 12),
       st.sampled_from([1, 2, 3, 8192]), st.integers(0, 4))
@settings(max_examples=600, deadline=None)
def test_blocks_are_the_lines_read_lines_gives(pieces, limit, size, n, chunk, ahead):
    data = b"".join(pieces)
    lines, err = _all(read_lines(_open(data, chunk), "p.nc", limit))
    if err is None:  # every byte is in the lines, each line with its ending
        assert "".join(lines) == data.decode("utf-8", "surrogateescape")
    elif lines:
        assert lines[-1].endswith(("\n", "\r"))

    # the lists read_blocks gives: the same lines, then the same refusal
    given_, given_err = _all(read_blocks(_open(data, chunk), "p.nc", limit, size))
    assert given_ == lines
    assert _place(given_err) == _place(err)

    # taken n at a time: the blocks of list(islice(lines, n)), the refusal at the same block
    it = read_lines(_open(data, chunk), "p.nc", limit)
    want, want_err = _blocks(lambda k: list(islice(it, k)), n)
    src = Lines(read_blocks(_open(data, chunk), "p.nc", limit, size))
    got, got_err = _blocks(src.take, n)
    assert got == want
    assert _place(got_err) == _place(want_err)
    assert src.taken == len(lines)  # every line given was taken, those of a block cut short by the refusal too

    # in lists of n, the refusal after the list of the lines before it (the path reader's)
    got = []
    with pytest.raises(PostprocError) if err else nullcontext() as refused:
        got += Lines(read_blocks(_open(data, chunk), "p.nc", limit, size)).lists(n)
    assert [line for block in got for line in block] == lines
    assert all(len(block) == n for block in got[:-1])
    assert all(got)
    assert _place(refused and refused.value) == _place(err)

    # one at a time first (the lines before a program's header), then n at a time
    ref = read_lines(_open(data, chunk), "p.nc", limit)
    src = Lines(read_blocks(_open(data, chunk), "p.nc", limit, size))
    first, first_err = _all(islice(src, ahead))
    ref_first, ref_err = _all(islice(ref, ahead))
    assert (first, _place(first_err)) == (ref_first, _place(ref_err))
    assert src.taken == len(first)
    if first_err is not None:
        return
    got, got_err = _blocks(src.take, n)
    want, want_err = _blocks(lambda k: list(islice(ref, k)), n)
    assert got == want
    assert _place(got_err) == _place(want_err)
    if err is None:
        assert src.taken == len(lines)


def test_a_file_is_read_as_readline_reads_it(tmp_path):
    # a "\r\n" cut between two reads, a lone "\r", a "\r" before "\r\n", no final line end;
    # then the same with a line one character too long
    p = tmp_path / "p.nc"
    for extra, refused in ((0, None), (3, 2)):
        long = "(" + "a" * (65_536 - 6 + extra) + ")\r\n"  # (its "\r" ends the first read)
        p.write_bytes(("G0\n" + long + "G1 X2\r\r\nG1 X3\rM2").encode())
        with open(p, encoding="utf-8", errors="surrogateescape", newline="") as fh:
            want, err = _all(read_lines(fh, str(p)))
        got, got_err = _all(iter_source_lines(p)[1])
        assert got == want
        assert _place(got_err) == _place(err)
        assert (err and err.lineno) == refused
    assert got == ["G0\n"]


def _program(tmp_path):
    """samples/pocket.nc three times over, its lines ended by "\\n", "\\r\\n" and "\\r" in turn
    (the last without an ending)."""
    body = (SAMPLES / "pocket.nc").read_text().splitlines()
    body = body[:1] + [line for line in body[1:] if line.strip() not in ("%", "M2", "M30")] * 3 + ["M2"]
    text = "".join(line + ("\n", "\r\n", "\r")[k % 3] for k, line in enumerate(body[:-1])) + body[-1]
    p = tmp_path / "p.nc"
    p.write_bytes(text.encode())
    return p, text


@pytest.mark.parametrize("chunk", [1, 2, 7, 40])
def test_a_program_taken_in_blocks_is_corrected_as_taken_line_by_line(tmp_path, chunk):
    p, text = _program(tmp_path)
    runs = []
    for lines in (iter(text.splitlines(keepends=True)), iter_source_lines(p)[1]):
        out: list[str] = []
        progress: list[int] = []
        rep = Corrector(ENGINE, SETUP, CorrectOptions(chunk_lines=chunk), path=str(p)).run(
            lines, out.append, progress=progress.append)
        runs.append(("".join(out), progress, rep.lines_in))
    assert runs[0] == runs[1]
    assert runs[0][2] == len(text.splitlines())


@pytest.mark.parametrize("chunk", [1, 7, 40])
def test_the_output_bound_names_the_last_line_read(tmp_path, chunk):
    # the lines are written a chunk at a time, once read: the place of an output that
    # passes its bound is the chunk's last line
    p, text = _program(tmp_path)
    progress: list[int] = []
    with pytest.raises(ResourceLimitError) as err:
        correct_file(p, tmp_path / "o.nc", ENGINE, SETUP,
                     CorrectOptions(chunk_lines=chunk, limits=Limits(max_output_lines=60)), progress=progress.append)
    assert (err.value.path, err.value.lineno) == (str(p), min(progress[-1] + chunk, len(text.splitlines())))
