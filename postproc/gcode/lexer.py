"""Lossless G-code tokenizer.

Every token keeps its exact source text, so ``tokens_to_src(lex(text)) == text`` for
any text that lexes. Only characters that cannot appear in G-code outside a comment
(control characters other than tab, form feed and line endings; non-ASCII) raise a
:class:`GcodeSyntaxError` naming ``path:line:col``. Everything else becomes a token;
the interpreter decides what it supports.

The same grammar is read in two forms:

- :func:`lex` (the reference): full token list with kinds and columns, and the place
  of anything that is not G-code;
- :mod:`postproc.gcode.scanner` (compiled where a compiler is): a chunk of text into
  columns, and :func:`scan_words`, the words of one line made only of words and blanks
  (``None`` for any other line, which then goes through :func:`lex`). Tests check that
  both agree token for token.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from postproc.errors import GcodeSyntaxError
from postproc.gcode import scanner

# Token kinds
WORD = "word"  # letter + number, e.g. "X 10.5"
LETTER = "letter"  # a letter not followed by a number (X#1, O<sub>, G[...])
NUMBER = "number"  # a number without a letter (inside expressions)
SPACE = "space"
COMMENT = "comment"  # ( ... )
OPEN_COMMENT = "open_comment"  # '(' without ')' before the end of the line
LINE_COMMENT = "line_comment"  # ; to the end of the line
PERCENT = "percent"
SLASH = "slash"  # block delete (or division inside an expression)
SYMBOL = "symbol"  # # [ ] = * < > @ ^ and other printable ASCII
NEWLINE = "newline"

# ASCII digits only: Python's \d also matches other scripts' digits ('X١٢'), which no
# controller reads (rs274: "bad number format") and float() would quietly take as 12.
NUMBER_RE = r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)"
# NUMBER_RE matched possessively (nothing after a number can start with a digit or a dot)
NUMBER_POSSESSIVE_RE = r"[+-]?+(?:[0-9]++\.?+[0-9]*+|\.[0-9]++)"
# Comments at the end of a line: in parentheses (no '(' inside), then one after ';'.
_END_COMMENTS = r"(?:\([^()\r\n]*\)[ \t]*+)*(?:;[^\r\n]*+)?"
# A line that moves nothing and sets nothing a correction reads (without its ending):
# blank, or an N word, an S word, program stop, spindle and coolant M words (M0 M1 M3-M5
# M7-M9) and comments. Read as such by the bulk writer and by diff's reader (the
# interpreter reads no geometry from it either).
QUIET_LINE_RE = (r"[ \t]*+(?:[Nn][ \t]*+[0-9]++[ \t]*+)?(?:[Ss][ \t]*+" + NUMBER_POSSESSIVE_RE + r"[ \t]*+)?"
                 r"(?:[Mm][ \t]*+0?[013-57-9](?![0-9.])[ \t]*+)*" + _END_COMMENTS)
# The words that set the tool length from a table entry, G43 H (the H number follows;
# G43.1 and G43.2 are not this): the bulk writer and diff's reader take a straight move
# that starts with them.
TOOL_LENGTH_RE = r"[Gg][ \t]*+43(?![0-9.])[ \t]*+[Hh][ \t]*+"
# A tool change alone on its line (without its ending): [N..] T<n> M6 or M6 T<n> (M06,
# T02 too) and comments; the T number in group 1 or 2 (of the pattern). It changes only
# the tool the interpreter holds (for a later G43 without H).
TOOL_LINE_RE = (r"[ \t]*+(?:[Nn][ \t]*+[0-9]++[ \t]*+)?"
                r"(?:[Tt][ \t]*+([0-9]++)[ \t]*+[Mm][ \t]*+0?6(?![0-9.])"
                r"|[Mm][ \t]*+0?6(?![0-9.])[ \t]*+[Tt][ \t]*+([0-9]++)(?![0-9.]))[ \t]*+" + _END_COMMENTS)

_MASTER = re.compile(
    r"(?P<newline>\r\n|\n|\r)"
    r"|(?P<space>[ \t\f\v]+)"
    r"|(?P<comment>\([^)\r\n]*\))"
    r"|(?P<open_comment>\([^)\r\n]*)"
    r"|(?P<line_comment>;[^\r\n]*)"
    rf"|(?P<word>[A-Za-z][ \t]*{NUMBER_RE})"
    r"|(?P<letter>[A-Za-z])"
    rf"|(?P<number>{NUMBER_RE})"
    r"|(?P<percent>%)"
    r"|(?P<slash>/)"
    r"|(?P<symbol>[!-~])"
)

_WORD_PARTS = re.compile(rf"([A-Za-z])[ \t]*({NUMBER_RE})")


@dataclass(frozen=True, slots=True)
class Token:
    """One token: its kind, exact source text, and where it starts (1-based)."""

    kind: str
    text: str
    lineno: int
    col: int

    @property
    def letter(self) -> str:
        """Upper-case letter of a WORD or LETTER token."""
        return self.text[0].upper()

    @property
    def number_text(self) -> str:
        """Raw number text of a WORD token (no letter, no blanks)."""
        m = _WORD_PARTS.match(self.text)
        return m.group(2) if m else ""

    @property
    def number_offset(self) -> int:
        """Offset of the number text inside the token text."""
        m = _WORD_PARTS.match(self.text)
        return m.start(2) if m else len(self.text)

    @property
    def value(self) -> float:
        return float(self.number_text)


def lex(text: str, path: str | None = None, lineno: int = 1) -> list[Token]:
    """Split ``text`` (any number of lines) into tokens that join back to ``text``."""
    tokens: list[Token] = []
    pos, n = 0, len(text)
    line_start = 0
    match = _MASTER.match
    while pos < n:
        m = match(text, pos)
        if m is None:
            ch = text[pos]
            raise GcodeSyntaxError(
                f"character {ch!r} (U+{ord(ch):04X}) is not G-code",
                path=path,
                lineno=lineno,
                col=pos - line_start + 1,
                hint="non-ASCII text and control characters may appear only inside comments",
            )
        kind = m.lastgroup
        if kind is None:  # every alternative of _MASTER is a named group
            raise AssertionError(f"token without a kind at {pos} in {text!r}")
        tokens.append(Token(kind, m.group(), lineno, pos - line_start + 1))
        pos = m.end()
        if kind == NEWLINE:
            lineno += 1
            line_start = pos
    return tokens


def tokens_to_src(tokens: list[Token]) -> str:
    """Exact inverse of :func:`lex`."""
    return "".join(t.text for t in tokens)


_LINE_SPLIT = re.compile(r"[^\r\n]*(?:\r\n|\n|\r)|[^\r\n]+$")


def split_lines(text: str) -> list[str]:
    """Lines with their own endings (LF, CRLF, CR or none at end of text)."""
    return _LINE_SPLIT.findall(text)


# A word of a block (letter, number text, its span, the letter's index): the scanner's.
Word = scanner.Word
# The words of a line made only of words and blanks, or None (the compiled scanner).
scan_words = scanner.scan_line


def words_from_tokens(tokens: list[Token]) -> list[Word]:
    """The same list as :func:`scan_words`, from :func:`lex` tokens of one line."""
    out: list[Word] = []
    for t in tokens:
        if t.kind == WORD:
            start = t.col - 1 + t.number_offset
            num = t.number_text
            out.append(Word(t.letter, num, start, start + len(num), t.col - 1))
    return out
