"""Cross-check of the word reading against pygcode (an independent G-code parser).

pygcode is only a reference here; it is not used to read or write programs.
"""

from pathlib import Path

import pytest

from postproc.gcode import lexer

pygcode = pytest.importorskip("pygcode")

ROOT = Path(__file__).parents[1]
FILES = sorted(p for p in (ROOT / "samples").glob("*") if p.suffix in {".nc", ".ngc", ".tap"})
FILES += sorted((ROOT / "tests" / "cases").glob("*.nc"))


def ours(line: str):
    words = lexer.words_from_tokens(lexer.lex(line))
    return sorted((letter, round(float(num), 9)) for letter, num, *_ in words)


def theirs(line: str):
    parsed = pygcode.Line(line.rstrip("\r\n"))
    if parsed.block is None:
        return []
    words = list(parsed.block.words)
    return sorted((w.letter.upper(), round(float(w.value), 9)) for w in words)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_words_agree_with_pygcode(path):
    checked = 0
    for line in lexer.split_lines(path.read_text()):
        if line.lstrip().startswith(("%", "/")):
            continue
        try:
            ref = theirs(line)
        except pygcode.exceptions.GCodeWordStrError:
            continue  # pygcode's own limits: blanks inside words, letters in some comments
        assert ours(line) == ref, line
        checked += 1
    assert checked > 5
