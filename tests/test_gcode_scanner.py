"""The chunk scanner reads the lexer's grammar: the same lines, words, spans and values;
plainscan's pieces join back to their line; numfmt's batch equals its one-value form, its
rounding is Python's, and its word rules are what they say."""

import math
import random
import struct

import pytest
from conftest import assert_offsets_cut_the_line
from hypothesis import given, settings
from hypothesis import strategies as st

from postproc.errors import GcodeSyntaxError
from postproc.gcode import lexer, numfmt, plainscan, scanner

ALPHABET = "GXYZIJKRFNMHgxyzn0123456789.+- \t\f()%;/#[]=\r\n\u00e9\u20ac"


def _check_chunk(text: str) -> None:
    cols = scanner.scan(text)
    lines = lexer.split_lines(text)
    assert len(cols) == len(lines)
    assert cols.line_start == [sum(map(len, lines[:i])) for i in range(len(lines) + 1)]
    for li, line in enumerate(lines):
        # a word's span is within its line, counted from the line's start
        got = [(cols.letter[k], line[cols.start[k]:cols.end[k]], cols.start[k], scanner.letter_pos(line, cols.start[k]))
               for k in range(cols.first_word[li], cols.first_word[li + 1])]
        for k in range(cols.first_word[li], cols.first_word[li + 1]):
            assert 0 <= scanner.letter_pos(line, cols.start[k]) < cols.end[k] <= len(line)
            num = line[cols.start[k]:cols.end[k]]
            assert math.copysign(1, cols.value[k]) == math.copysign(1, float(num))
            assert cols.value[k] == float(num)
        try:
            tokens = lexer.lex(line)
        except GcodeSyntaxError:
            assert not cols.plain[li]
            continue
        ref = [(t.letter, t.number_text, t.col - 1 + t.number_offset, t.col - 1)
               for t in tokens if t.kind == lexer.WORD]
        assert got == ref
        plain = all(t.kind == lexer.WORD or t.kind == lexer.NEWLINE or (t.kind == lexer.SPACE and not t.text.strip(" \t"))
                    for t in tokens)
        assert cols.plain[li] == plain
        assert (lexer.scan_words(line) is not None) == plain


@given(st.text(alphabet=ALPHABET, max_size=200))
@settings(max_examples=300, deadline=None)
def test_scanner_agrees_with_lexer(text):
    _check_chunk(text)


def test_scanner_on_samples_and_numbers():
    _check_chunk("N10 G1 X1.5 Y-.25 Z+3. (c) F100\r\nG2X1Y2I-0J0.000000000000000000001\nX12345678901234567.5")
    cols = scanner.scan("X-0\nY0.1\n")
    assert math.copysign(1, cols.value[0]) == -1
    assert cols.value[1] == 0.1


def test_number_values_are_floats_of_their_text():
    """The scanner's values are bit for bit ``float`` of the number text, sign of zero
    included: short numbers (at most 15 digits) by one division, longer by ``float``."""
    rng = random.Random(7)
    texts = ["0", "-0", "+0.", ".5", "-.5", "5.", "-0.0000", "0.1", "228.47505", "999999999999999.",
             "123456789012345", "1234567890123456", "0.000000000000001", "0.0000000000000001",
             "000000000000000000001.5", "9007199254740993"]
    for _ in range(50_000):
        digits = "".join(rng.choice("0123456789") for _ in range(rng.randint(1, 18)))
        p = rng.randint(0, len(digits))
        texts.append(rng.choice(["", "-", "+"]) + (digits[:p] + "." + digits[p:] if rng.random() < 0.8 else digits))
    for t in texts:
        b = t.encode()
        assert struct.pack("d", scanner.number_value(b, 0, len(b))) == struct.pack("d", float(t)), t
    cols = scanner.scan(" ".join("X" + t for t in texts))
    assert [struct.pack("d", v) for v in cols.value] == [struct.pack("d", float(t)) for t in texts]


@given(st.lists(st.sampled_from(["N10", "G0", "G01", "G2", "G43", "H2", "X1.5", "x-2", "Y.5", "Z3.", "I1", "J-2",
                                 "F100", "K1", " ", "\t", "(c)", "S1"]), max_size=10),
       st.sampled_from(["", "\n", "\r\n"]))
@settings(max_examples=300, deadline=None)
def test_pieces_give_the_offsets_of_the_words(words, ending):
    line = "".join(words) + ending
    cols = scanner.scan(line)
    p = plainscan.pieces(line, cols)
    if not len(cols) or not (any(col[0] for col in p.at) or any(h[0] for h in p.has) or p.motion[0] >= 0
                             or p.tlo[0] >= 0):
        return  # not a plain move (or a blank line): nothing named
    assert_offsets_cut_the_line(line, [col[0] for col in p.at], [h[0] for h in p.has], [v[0] for v in p.value],
                                p.late[0])
    toks = {t.letter.upper(): t.number_text for t in lexer.lex(line) if t.kind == lexer.WORD}
    for k in range(5):
        if p.has[k][0]:
            assert p.frac[k][0] == lexer_decimals(toks["XYZIJ"[k]])
    head = [t for t in lexer.lex(line[:p.at[0][0]]) if t.kind == lexer.WORD]
    motions = [t for t in head if t.letter.upper() == "G" and t.number_text != "43"]
    assert p.motion[0] == (int(motions[0].number_text) if motions else -1)
    lengths = [t for t in head if t.letter.upper() == "H"]
    assert p.tlo[0] == (int(lengths[0].number_text) if lengths else -1)
    assert p.has[plainscan.F][0] == ("F" in toks)


def lexer_decimals(number: str) -> int:
    _, dot, frac = number.partition(".")
    return len(frac) if dot else 0


@given(st.lists(st.floats(min_value=-1e6, max_value=1e6), max_size=30), st.integers(0, 8), st.booleans())
@settings(max_examples=300, deadline=None)
def test_fmt_all_is_fmt(values, d, mixed):
    decimals = [(d + i % 3) if mixed else d for i in range(len(values))]
    values += [-0.0, -1e-12, -(10.0 ** -d) / 2]
    decimals += [d, d, d]
    assert numfmt.fmt_all(values, decimals, "X") == ["X" + numfmt.fmt(v, k) for v, k in zip(values, decimals, strict=True)]
    assert all(not t.startswith("X-") or t.strip("X-0.") for t in numfmt.fmt_all(values, decimals, "X"))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("mixed", [False, True])
def test_fmt_all_refuses_what_is_not_finite(bad, mixed):
    values = [1.5, 1e308, 1e308, bad, -2.0]
    decimals = [4, 4, 4, 4, 5 if mixed else 4]
    with pytest.raises(ValueError, match="cannot write"):
        numfmt.fmt_all(values, decimals, "X")


def test_fmt_all_writes_finite_values_whose_sum_overflows():
    assert numfmt.fmt_all([1e308, 1e308, -0.0], [1, 1, 1], "")[1:] == ["%.1f" % 1e308, "0.0"]  # noqa: UP031


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


@given(st.floats(allow_nan=True, allow_infinity=True), st.integers(-3, 30))
@settings(max_examples=2000, deadline=None)
def test_round_to_is_round(x, d):
    assert _bits(numfmt.round_to(x, d)) == _bits(round(x, d))


def test_round_to_is_round_at_and_beside_halves():
    """Near a half of the last digit the product x 10^d is off by its rounding: there the
    answer must still be round's, bit for bit (the doubles beside each half, and beside
    the values a half rounds to)."""
    rng = random.Random(7)
    checked = 0
    for _ in range(20000):
        d = rng.randrange(0, 9)
        k = rng.randrange(-10**9, 10**9)
        for centre in ((k + 0.5) / 10**d, k / 10**d, (k + 0.5) * 10.0 ** -d):
            x = centre
            for _step in range(3):
                x = math.nextafter(x, math.inf)
            for _step in range(7):
                assert _bits(numfmt.round_to(x, d)) == _bits(round(x, d)), (x, d)
                x = math.nextafter(x, -math.inf)
                checked += 1
    for x, d in ((0.125, 2), (0.375, 2), (2.675, 2), (-2.5, 0), (2.5, 0), (-0.0004, 3), (-0.0, 2),
                 (4503599627370495.5, 0), (1e300, 22), (5e-324, 22), (1.5, 23), (15.0, -1)):
        assert _bits(numfmt.round_to(x, d)) == _bits(round(x, d)), (x, d)
    assert checked == 20000 * 3 * 7


def test_a_word_within_half_a_step_keeps_its_text():
    half = numfmt.half_unit(3)
    assert half == 0.0005
    assert numfmt.half_unit(400) == 0.0
    assert numfmt.word_text(1.0 + 0.9 * half, 1.0, 1, 3) == ""  # within half a step: kept
    assert numfmt.word_text(half, 0.0, 1, 3) == "0.001"  # half a step: written anew
    assert numfmt.word_text(1.25, 1.2, 1, 3) == "1.250"  # the output's decimals...
    assert numfmt.word_text(1.25, 1.23456, 5, 3) == "1.25000"  # ...or the word's own, if more
    assert numfmt.word_text(-1e-9, 1.0, 0, 3) == "0.000"  # never -0
    with pytest.raises(ValueError, match="cannot write nan"):
        numfmt.word_text(math.nan, 1.0, 0, 3)  # a NaN target is refused, never kept


def test_a_word_is_added_half_a_step_away_and_reaches_its_text():
    assert numfmt.added_text(0.0004, 0.0, 1.0, 7.0004, 3) == ""
    assert numfmt.added_text(0.0005, 0.0, 1.0, 7.0006, 3) == "7.001"  # half a step away: added
    assert numfmt.added_text(25.4 * 1.0004, 25.4, 25.4, 1.0004, 3) == ""  # 10 um, but in program units (inch)
    assert numfmt.added_text(5.0, math.nan, 1.0, 5.0, 3) == ""  # an axis never positioned: no word
    with pytest.raises(ValueError, match="cannot write nan"):
        numfmt.added_text(math.nan, 1.0, 1.0, math.nan, 3)  # a NaN target is refused, never skipped
    assert numfmt.reached("7.001", 7.0005) == 7.001
    assert math.copysign(1.0, numfmt.reached("0.000", -0.0001)) == -1.0  # a zero keeps the value's sign


@given(st.lists(st.tuples(st.floats(-1e4, 1e4), st.floats(-1e-3, 1e-3), st.integers(0, 6), st.integers(0, 6)),
                max_size=40))
@settings(max_examples=200, deadline=None)
def test_word_texts_is_word_text(words):
    values = [own + dv for own, dv, _, _ in words]
    own = [w[0] for w in words]
    own_dec, dec = [w[2] for w in words], [w[3] for w in words]
    # half a step exactly (written anew), and just within it (kept)
    for d in (2, 3, 4):
        h = numfmt.half_unit(d)
        values += [h, -h, 0.75 * h]
        own += [0.0, 0.0, 0.0]
        own_dec += [d, 0, 1]
        dec += [d, d, d]
    at = [3 * k + 1 for k in range(len(values))]  # each word's place in the texts put into
    put = ["."] * (3 * len(values) + 1)
    changed, texts = numfmt.word_texts(values, own, own_dec, dec, (put, at))
    one = [numfmt.word_text(*w) for w in zip(values, own, own_dec, dec, strict=True)]
    assert changed == [k for k, t in enumerate(one) if t]
    assert texts == [one[k] for k in changed]
    assert put == ["."] + [x for t in one for x in (t or ".", ".", ".")]
    assert numfmt.word_texts(values, own, own_dec, dec) == (changed, texts)


@pytest.mark.parametrize(("text", "longest"), [
    ("G1 X1.5 Y-22.25\n", 2), ("X123456789.123456\n", 9), ("X-0000000001\n", 10), ("Y+.1234567890123\n", 0),
    ("(X12345678901)\nX1\n", 1), ("G1 X1e9\n", 1), ("N12 X" + "9" * 400 + "\n", 400), ("", 0),
])
def test_the_longest_integer_part_of_the_words(text, longest):
    # the bulk lane leaves a chunk with a number of ten or more digits before its point to
    # the interpreter, which refuses a value beyond its bound at its place
    assert scanner.scan(text).longest == longest


def test_a_chunk_with_a_long_number_in_a_word_is_the_interpreters():
    from postproc.gcode import bulk

    assert bulk.scan(["G0 X1 Y1 Z1\n", "G1 X1234567890\n"]) is None
    assert bulk.scan(["G0 X1 Y1 Z1\n", "G1 X-0123456789\n"]) is None
    assert bulk.scan(["G0 X1 Y1 Z1\n", "G1 X123456789.0123456789\n"]) is not None
    assert bulk.scan(["G0 X1 Y1 Z1\n", "(part 12345678901)\n", "G1 X2\n"]) is not None  # in a comment: no word


def test_edit_line_puts_texts_at_spans_in_any_order():
    from postproc.gcode import runwords

    line = "N10 G1 X1.5 Y-2 (keep) F100\r\n"
    assert runwords.edit_line(line, []) is line
    # the spans of X's and Y's numbers, and an insertion after Y's
    edits = [(13, 15, "-2.25"), (8, 11, "1.499"), (15, 15, " Z3")]
    assert runwords.edit_line(line, edits) == "N10 G1 X1.499 Y-2.25 Z3 (keep) F100\r\n"
    assert runwords.edit_line(line, list(reversed(edits))) == runwords.edit_line(line, edits)
    # a word added at the ")" of X=AC(10) (Sinumerik) goes after it
    assert runwords.edit_line("G1 X=AC(10)\n", [(10, 10, " Y2")]) == "G1 X=AC(10) Y2\n"
