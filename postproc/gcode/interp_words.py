"""A line of G-code into the words of its block: the dialect's reader (ISO words, or a
Sinumerik block with its frames and cycle calls), every construct postproc does not read
refused at its place, with what it is and what to do instead."""

from __future__ import annotations

import re

from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.gcode import lexer
from postproc.gcode.interp_core import AXES, InterpreterCore, NeedsExpansion, gkey

_COMMENTS = re.compile(r"\([^)]*\)?|;.*")
# tokens of a line that carry no word
_BLANK_KINDS = frozenset((lexer.SPACE, lexer.COMMENT, lexer.LINE_COMMENT, lexer.NEWLINE))
_OWORD = re.compile(r"^\s*/?\s*(?:N\s*\d+\s*)?O\s*(?:\d+|<[^>]*>)\s*([A-Z]+)?")
_MACRO_KEYWORDS = re.compile(r"\b(IF|WHILE|GOTO|END|DO)\s*[\[\d]|\bGOTO")
# a Sinumerik block that is a name alone, or a name with arguments: perhaps a subprogram call
_SINUMERIK_NAME_CALL = re.compile(r"(?i)^\s*(?:N\d+\s+)?[A-Z_]\w*\s*(?:\(.*\))?\s*(?:P\s*=?\s*\d+)?\s*$")
_ASSIGN = re.compile(r"#\s*(?:\d+|<[^>]*>|\[)[^=]*=")


def classify_construct(line: str) -> tuple[str, str]:
    """What an unsupported line really is: ``(construct, hint)`` for the refusal."""
    text = _COMMENTS.sub(" ", line).upper()
    expand_hint = ("postproc expands subprograms, loops, parameters and expressions when they are defined "
                   "in the program (or on --subroutine-path); this one could not be expanded")
    m = _OWORD.match(text)
    if m and m.group(1):
        return f"LinuxCNC O-word '{m.group(1).lower()}' (subroutine or flow control)", expand_hint
    m = _MACRO_KEYWORDS.search(text)
    if m:
        kw = m.group(1) or "GOTO"
        return f"Fanuc custom macro {kw} statement", expand_hint
    if _ASSIGN.search(text):
        return "parameter assignment '#...='", expand_hint
    if "#" in text:
        return "parameter reference '#'", expand_hint
    if "[" in text or "]" in text:
        return "expression '[ ]'", expand_hint
    if "@" in text or "^" in text:
        return "polar coordinate word '@'/'^'", "post the program in Cartesian coordinates"
    if "<" in text:
        return "named O-word or parameter '< >'", expand_hint
    return "", ""


def blank_nested_comments(line: str) -> str:
    """The line with the inside of each outermost balanced ( ... ) blanked, so that a
    nested comment lexes as one comment at the same columns."""
    out = list(line)
    depth = 0
    for i, ch in enumerate(line):
        if ch == ";" and depth == 0:
            break
        if ch == "(":
            if depth > 0:
                out[i] = " "
            depth += 1
        elif ch == ")" and depth > 0:
            depth -= 1
            if depth > 0:
                out[i] = " "
    return "".join(out)


def _is_program_number(tokens: list[lexer.Token], after_n: bool = False) -> bool:
    """``O1234``, ``O0001 (NAME)``, ``:1234``: a program number or label, nothing else;
    with ``after_n`` also ``N1 O2 (NAME)`` (Fadal)."""
    content = [t for t in tokens if t.kind not in (lexer.SPACE, lexer.COMMENT, lexer.LINE_COMMENT,
                                                       lexer.NEWLINE)]
    if after_n and len(content) == 2 and content[0].kind == lexer.WORD and content[0].letter == "N":
        content = content[1:]
    if len(content) == 1:
        t = content[0]
        return t.kind == lexer.WORD and t.letter == "O" and "." not in t.text and "-" not in t.text
    if len(content) == 2:
        a, b = content
        return a.kind == lexer.SYMBOL and a.text == ":" and b.kind == lexer.NUMBER and b.text.isdigit()
    return False


class WordsMixin(InterpreterCore):
    """Reading a line into its block's words (mixed into :class:`~postproc.gcode.interp.Interpreter`)."""

    def _slow_words(self, lineno: int, line: str) -> tuple[list[lexer.Word], bool]:
        if not self._iso_blocks:
            return self._sinumerik_words(lineno, line)
        if self.d.comments_nest and line.count("(") > 1:
            line = blank_nested_comments(line)
        if self.d.header_forms and any(re.match(p, line) for p in self.d.header_forms):
            return [], False  # the dialect's own header line ("$NAME.MIN%")
        if "$" in line or "%" in line:
            self._foreign(line, lineno)  # ";$PATH=", "%_N_..._MPF", "$NAME.MIN%" of another dialect
        try:
            tokens = lexer.lex(line, self.path, lineno)
        except GcodeSyntaxError:
            self._foreign(line, lineno)
            what, hint = classify_construct(line)
            if what:
                raise self.error(self._construct_error(what), what, lineno, 1, hint=hint) from None
            raise
        first = next((t for t in tokens if t.kind != lexer.SPACE), None)
        if first is not None and first.kind == lexer.PERCENT and len(tokens) > 2:
            if self.d.text_after_percent == "ignored":
                return [], False  # '%' tape mark: the controller ignores the rest of the line
            raise self.error(GcodeSyntaxError, "'%' must stand alone on its line", lineno, first.col,
                            hint="LinuxCNC rejects text after '%' (\"Bad character '%' used\")")
        if _is_program_number(tokens, self.d.numbered_program_line):
            return [], False
        for tok in tokens:
            if tok.kind in (lexer.WORD, lexer.LETTER, lexer.SYMBOL) and (tok.letter == "O" or tok.text in "#[<"):
                if self.d.refused:
                    self._foreign(line, lineno)  # the dialect's own constructs first (Fadal's # macros)
                what, hint = classify_construct(line)
                if what:
                    raise self.error(self._construct_error(what), what, lineno, tok.col, hint=hint)
            if tok.kind in (lexer.WORD, lexer.LETTER) and tok.letter == "O":
                self._foreign(line, lineno)
                raise self.error(self._construct_error("O-word"), "O-word (subroutine or flow control)", lineno,
                                tok.col,
                                hint="O words other than a program number are expanded only when their "
                                     "subroutine is in the program or on --subroutine-path")
        return self._plain_words(tokens, line, lineno)

    def _sinumerik_words(self, lineno: int, line: str) -> tuple[list[lexer.Word], bool]:
        """A Sinumerik block's words (:mod:`postproc.gcode.sinumerik`); its constructs that
        postproc does not read are refused by their names first."""
        from postproc.gcode import sinumerik

        code = sinumerik.code_of(line)
        if code.strip():
            self._foreign(code, lineno)
        try:
            blk = sinumerik.read_block(line, self.path, lineno, self.variables)
        except UnsupportedGcodeError as exc:
            if self.may_expand and _SINUMERIK_NAME_CALL.match(code):  # NAME or NAME(...): a subprogram call?
                raise self.error(NeedsExpansion, exc.message, lineno, exc.col or 1, hint=exc.hint) from None
            raise
        g = {gkey(w.number) for w in blk.words if w.letter == "G"}
        incremental = True if 910 in g else False if 900 in g else self.state.incremental
        centre_ac = [letter for letter, _ in blk.absolute if letter in "IJK"]
        if centre_ac:
            given = [w.letter for w in blk.words if w.letter in "IJK"]
            if len(centre_ac) != len(given):
                col = next(c for letter, c in blk.absolute if letter in "IJK")
                raise self.error(UnsupportedGcodeError, "Sinumerik centre words partly =AC() (absolute) and partly "
                                "incremental", lineno, col, hint="give every centre word of the arc as =AC(), or none")
            self._arc_absolute_once = True  # I=AC() J=AC(): the centre in work coordinates, this block
        for letter, col in blk.absolute:
            if incremental and letter not in "IJK":
                raise self.error(UnsupportedGcodeError, f"Sinumerik {letter}=AC() (absolute for one word) in G91",
                                lineno, col,
                                hint="post the coordinate in the program's distance mode (G90/G91)")
        for letter, col in blk.incremental:
            if not incremental and letter in "XYZABC":
                raise self.error(UnsupportedGcodeError, f"Sinumerik {letter}=IC() (incremental for one word) in G90",
                                lineno, col, hint="post the coordinate in the program's distance mode (G90/G91)")
        if blk.call is not None:
            name = f"MCALL {blk.call.name}" if blk.mcall else blk.call.name
            others = [w for w in blk.words if w.letter != "N"]
            if others or blk.frame:
                raise self.error(UnsupportedGcodeError, f"Sinumerik {name} with other words in its block", lineno,
                                blk.call.col, hint="write the cycle call in a block of its own")
            self.call_line, self.call_col = name, blk.mcall_col if blk.mcall else blk.call.col
            if blk.mcall:
                self.modal_call = blk.call
            else:
                self._cycle_due = blk.call
            return [], blk.block_delete
        if blk.mcall:
            self.modal_call = None  # a bare MCALL ends the modal call
        elif self.modal_call is not None and any(w.letter in AXES for w in blk.words):
            self._cycle_due = self.modal_call
        if blk.ends:
            self.ended = True  # RET: the end of the program (the block's own words still run)
        if blk.frame:
            self._sinumerik_frame(blk.frame, blk.words, lineno, blk.rpl)
            return [], blk.block_delete
        return blk.words, blk.block_delete

    def _sinumerik_frame(self, kind: str, words: list[lexer.Word], lineno: int,
                         rpl: tuple[float, int] | None) -> None:
        """The programmable frame (:mod:`postproc.gcode.frames`): TRANS/ROT/SCALE/MIRROR replace
        it (alone: delete it), their A forms add to it. Its translation is kept with the
        G52/G92 shift, its rotation, scale and mirror in ``state.frame``."""
        from postproc.gcode import frames

        st = self.state
        given = {w.letter: (float(w.number), w.letter_pos + 1) for w in words if w.letter != "N"}
        bad = [k for k in given if k not in AXES]
        if bad:
            raise self.error(UnsupportedGcodeError, f"Sinumerik frame with {bad[0]} (the frame's X, Y, Z are read)",
                            lineno, given[bad[0]][1], hint="post the program in the coordinates the frame gives")
        angle = None
        if kind.endswith("ROT"):
            tilt = next((a for a in "XY" if a in given), None)
            if tilt is not None:
                raise self.error(UnsupportedGcodeError, f"Sinumerik {kind} {tilt} (a rotation about {tilt} tilts the "
                                "plane; rotations about Z are read)", lineno, given[tilt][1],
                                hint="post the program in the coordinates the frame gives")
            if rpl is not None and "Z" in given:
                raise self.error(UnsupportedGcodeError, f"Sinumerik {kind} with both Z and RPL", lineno, rpl[1])
            if rpl is not None and st.plane != 170:
                raise self.error(UnsupportedGcodeError, f"Sinumerik {kind} RPL= in a plane other than G17 "
                                "(a rotation about X or Y)", lineno, rpl[1])
            angle = rpl[0] if rpl is not None else given["Z"][0] if "Z" in given else None
        if kind.endswith("SCALE") and any(v == 0.0 for v, _c in given.values()):
            raise self.error(GcodeSyntaxError, f"Sinumerik {kind} with a factor 0", lineno,
                            min(c for _v, c in given.values()))
        st.frame, st.g92 = frames.next_frame(kind, st.frame, st.g92, {a: v for a, (v, _c) in given.items()}, angle,
                                             st.unit_mm)
        self.run_shift = None

    def _plain_words(self, tokens: list[lexer.Token], line: str, lineno: int) -> tuple[list[lexer.Word], bool]:
        """The words of a lexed line and whether it starts with '/' (block delete);
        anything else than words, blanks and comments is refused."""
        words = []
        block_delete = False
        seen_content = False
        for tok in tokens:
            kind = tok.kind
            if kind == lexer.WORD:
                seen_content = True
                start = tok.col - 1 + tok.number_offset
                num = tok.number_text
                words.append(lexer.Word(tok.letter, num, start, start + len(num), tok.col - 1))
            elif kind == lexer.SLASH:
                if seen_content:
                    raise self.error(UnsupportedGcodeError, "'/' inside a block (division in an expression)",
                                    lineno, tok.col)
                block_delete = True
            elif kind not in _BLANK_KINDS:
                self._refuse_token(tok, tokens, seen_content, line, lineno)
        return words, block_delete

    def _refuse_token(self, tok: lexer.Token, tokens: list[lexer.Token], seen_content: bool, line: str,
                      lineno: int) -> None:
        """Raise the error for a token that is not a word, blank, comment or '/' (a '%'
        standing alone on its line passes)."""
        kind = tok.kind
        if kind == lexer.PERCENT:
            if seen_content or any(t.kind in (lexer.WORD, lexer.LETTER, lexer.SYMBOL, lexer.NUMBER) for t in tokens):
                raise self.error(GcodeSyntaxError, "'%' must stand alone on its line", lineno, tok.col)
        elif kind == lexer.OPEN_COMMENT:
            raise self.error(GcodeSyntaxError, "comment '(' is not closed on its line", lineno, tok.col,
                            hint="add the closing ')'")
        elif kind == lexer.LETTER:
            self._foreign(line, lineno)
            what, hint = classify_construct(line)
            if what:
                raise self.error(self._construct_error(what), what, lineno, tok.col, hint=hint)
            raise self.error(UnsupportedGcodeError,
                            f"word {tok.letter} without a plain number (macro, expression or parameter)",
                            lineno, tok.col, hint="expand macros and expressions before correcting")
        elif kind == lexer.SYMBOL:
            self._foreign(line, lineno)
            what, hint = classify_construct(line) if tok.text in "#[]@^<" else ("", "")
            if what:
                raise self.error(self._construct_error(what), what, lineno, tok.col, hint=hint)
            raise self.error(GcodeSyntaxError, f"unexpected character {tok.text!r}", lineno, tok.col)
        elif kind == lexer.NUMBER:
            raise self.error(GcodeSyntaxError, f"number {tok.text!r} without a letter", lineno, tok.col)

