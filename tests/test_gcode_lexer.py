"""The tokenizer is lossless; the fast line scanner agrees with it."""

from pathlib import Path

import pytest
from conftest import FULL_CORPUS, representative
from hypothesis import given, settings
from hypothesis import strategies as st

from postproc.errors import GcodeSyntaxError
from postproc.gcode import lexer

ROOT = Path(__file__).parents[1]
CORPUS = Path(__file__).parents[2] / "shared" / "corpus"

GCODE_ALPHABET = "GXYZIJKRFNMSTOPgxyz0123456789.+- \t()%;/#[]=*<>\r\n@^"


def _program_files():
    files = sorted((ROOT / "samples").glob("*.*"))
    if CORPUS.is_dir():
        corpus = sorted(p for p in CORPUS.rglob("*") if p.is_file() and p.name != "README.md")
        # every file with POSTPROC_FULL_CORPUS=1, else every one under 2000 lines and of
        # the longer ones a subset naming every construct, source and suffix they name
        # (conftest.representative)
        files += corpus if FULL_CORPUS else representative(corpus, every_below=2_000)
    return files


@given(st.text(alphabet=GCODE_ALPHABET, max_size=200))
@settings(max_examples=200, deadline=None)
def test_roundtrip_on_gcode_like_text(text):
    assert lexer.tokens_to_src(lexer.lex(text)) == text


@given(st.text(max_size=120))
@settings(max_examples=200, deadline=None)
def test_roundtrip_or_error_naming_the_character_on_any_text(text):
    err = None
    try:
        tokens = lexer.lex(text, path="p.nc")
    except GcodeSyntaxError as exc:
        err = exc
    if err is not None:
        # errors only for characters that cannot be G-code outside comments
        line = lexer.split_lines(text)[err.lineno - 1]
        ch = line[err.col - 1]
        assert not (" " <= ch <= "~")
        assert ch != "\t"
        assert str(err).startswith(f"p.nc:{err.lineno}:{err.col}:")
        return
    assert lexer.tokens_to_src(tokens) == text


@given(st.text(alphabet="GXYZFN0123456789.+- \txyz", max_size=60),
       st.sampled_from(["", "\n", "\r\n", "\r"]))
@settings(max_examples=200, deadline=None)
def test_fast_scanner_agrees_with_reference(body, ending):
    line = body + ending
    fast = lexer.scan_words(line)
    if fast is None:
        return
    tokens = lexer.lex(line)
    assert all(t.kind in (lexer.WORD, lexer.SPACE, lexer.NEWLINE) for t in tokens)
    assert fast == lexer.words_from_tokens(tokens)


def test_tokens_keep_raw_text_and_columns():
    line = "N10 g1 X 10.50 y-.5(cmt) ;tail\r\n"
    toks = lexer.lex(line)
    words = [(t.letter, t.number_text, t.col) for t in toks if t.kind == lexer.WORD]
    assert words == [("N", "10", 1), ("G", "1", 5), ("X", "10.50", 8), ("Y", "-.5", 16)]
    kinds = [t.kind for t in toks]
    assert lexer.COMMENT in kinds
    assert lexer.LINE_COMMENT in kinds
    assert kinds[-1] == lexer.NEWLINE
    assert lexer.scan_words(line) is None  # comments: slow path
    assert lexer.scan_words("X 10.50 Y2\n") == [("X", "10.50", 2, 7, 0), ("Y", "2", 9, 10, 8)]


def test_non_gcode_character_is_an_error_with_place():
    with pytest.raises(GcodeSyntaxError) as e:
        lexer.lex("G0 X1\nG1 X\x01\n", path="f.nc")
    assert (e.value.lineno, e.value.col) == (2, 5)
    # but anything goes inside a comment
    text = "(température \x01 ok)\n; ünïcode\n"
    assert lexer.tokens_to_src(lexer.lex(text)) == text


def test_split_lines_keeps_every_ending():
    text = "a\r\nb\nc\rd"
    assert lexer.split_lines(text) == ["a\r\n", "b\n", "c\r", "d"]
    assert "".join(lexer.split_lines(text)) == text


@pytest.mark.parametrize("path", _program_files(), ids=lambda p: p.name)
def test_every_program_file_roundtrips_or_names_the_place(path):
    text = path.read_bytes().decode("utf-8", errors="surrogateescape")
    err = None
    try:
        tokens = lexer.lex(text, path=str(path))
    except GcodeSyntaxError as exc:
        err = exc
    if err is not None:
        assert err.lineno is not None
        assert err.col is not None
        return
    assert lexer.tokens_to_src(tokens) == text
