"""Expansion of LinuxCNC parameters, expressions and O-word control.

Each construct is checked against LinuxCNC's own interpreter (rs274): the program as
written and its expansion must give the same canonical motions. Hand-derived flat
text checks the rewriting itself where rs274 is not needed.
"""

from __future__ import annotations

import re

import pytest
from oracle import requires_rs274, run_rs274, run_rs274_many, same_motions

from postproc.errors import GcodeSyntaxError, PostprocError
from postproc.gcode.expand import ExpansionError, SourceLine, expand, needs_expansion
from postproc.gcode.expr import format_number
from postproc.gcode.lexer import split_lines

HEAD = "G21 G17 G90 G94 F100\n"


def flat(text: str, **kw) -> list[SourceLine]:
    return list(expand(split_lines(text), **kw))


def flat_text(text: str, **kw) -> str:
    return "".join(sl.text for sl in flat(text, **kw))


# One program per construct; each must move the machine in a way that depends on it.
PROGRAMS = {
    "numbered": HEAD + "#1 = 2.5\n#31 = [#1 * 2]\nG1 X#1 Y#31\nG1 X-#1 Y[-#31]\nM2\n",
    "named_local_global": HEAD + "#<w> = 3\n#<_g> = [#<w> + 1]\nG1 X#<w> Y#<_g>\nG1 X#<_G> Y#<W>\nM2\n",
    "blanks_in_names": HEAD + "#<my width> = 4\nG1 X#<mywidth> Y # < my width >\nM2\n",
    "settings_after_line": HEAD + "#1 = 1\n#1 = 5 G1 X#1 #2 = [#1 + 1]\nG1 X#1 Y#2\nM2\n",
    "indirect": HEAD + "#1 = 2\n#2 = 7\nG1 X##1 Y#[#1 - 1]\nM2\n",
    "precedence": HEAD + "G1 X[1 + 2 * 3 - 4 / 2] Y[2 ** 3 ** 2 / 32] Z[2 * 3 ** 2]\n"
    "G1 X[-7 MOD 3] Y[7 MOD -3] Z[-2 ** 2]\nG1 X[1 LT 2 AND 3 GT 4] Y[1 + 1 EQ 2] Z[5 - 3 - 1]\nM2\n",
    "logic": HEAD + "G1 X[1 EQ 1.00001] Y[2 NE 2.00001] Z[3 XOR 0]\nG1 X[0 OR 0] Y[4 AND 2] Z[2 GE 2]\n"
    "G1 X[1 LE 0] Y[3 GT 3] Z[-1 LT 0]\nM2\n",
    "functions": HEAD + "G1 X[SIN[30] * 10] Y[COS[60] * 10] Z[TAN[45]]\n"
    "G1 X[ASIN[0.5]] Y[ACOS[0.5]] Z[ATAN[1]/[-1]]\n"
    "G1 X[SQRT[16] + ABS[-2]] Y[EXP[1]] Z[LN[10]]\n"
    "G1 X[FIX[-1.5]] Y[FUP[-1.5]] Z[ROUND[-2.5]]\nG1 X[FIX[2.7]] Y[FUP[2.1]] Z[ROUND[2.4999]]\nM2\n",
    "exists": HEAD + "#<a> = 1\nG1 X[EXISTS[#<a>]] Y[EXISTS[#<b>]] Z[EXISTS[#<_value>]]\nM2\n",
    "unary_sign": HEAD + "#1 = 3\nG1 X-#1 Y-[#1 + 1] Z+#1\nG1 X[-SIN[90]] Y[- -2]\nM2\n",
    "words_from_expressions": HEAD + "#1 = 1\n#2 = 0.5\nG[#1] X10 F[200 * #2]\nG[#1 + 1] X0 Y0 I-5 J0\n"
    "G[2 + #1] X10 R5\nM2\n",
    "sub_call_args": HEAD + "o100 sub\n  G1 X#1 Y#2 Z#3\no100 endsub\no100 call [1] [2 + 1]\n"
    "#1 = 9\no100 call [#1]\nG1 X#1\nM2\n",
    "sub_locals_restored": HEAD + "#1 = 11\n#<v> = 4\no7 sub\n  #1 = 99\n  #<v> = 5\n  G1 X#1 Y#<v>\n"
    "o7 endsub\no7 call [3]\nG1 X#1 Y#<v>\nM2\n",
    "sub_defined_after_call": HEAD + "o200 call [7]\nM2\no200 sub\n  G1 X#1\no200 endsub\n",
    "return_value": HEAD + "o<twice> sub\n  o<twice> return [#1 * 2]\no<twice> endsub\n"
    "o<twice> call [4]\nG1 X#<_value> Y#<_value_returned>\no<twice> call [1]\nG1 Z#<_value>\nM2\n",
    "endsub_value": HEAD + "o1 sub\no1 endsub [#1 + 10]\no1 call [2]\nG1 X#<_value>\nM2\n",
    "nested_calls": HEAD + "o1 sub\n  G1 X#1\n  o2 call [#1 + 1]\n  G1 Y#1\no1 endsub\n"
    "o2 sub\n  G1 Z#1\no2 endsub\no1 call [3]\no1 call [5]\nM2\n",
    "if_elseif_else": HEAD + "#1 = 0\no9 while [#1 LT 4]\n  #1 = [#1 + 1]\n"
    "  o10 if [#1 EQ 1]\n    G1 X1\n  o10 elseif [#1 EQ 2]\n    G1 X2\n  o10 elseif [#1 EQ 3]\n    G1 X3\n"
    "  o10 else\n    G1 X4\n  o10 endif\no9 endwhile\nM2\n",
    "while": HEAD + "#1 = 0\no1 while [#1 LT 5]\n  G1 X#1 Y[#1 * #1]\n  #1 = [#1 + 1]\no1 endwhile\nG1 Z#1\nM2\n",
    "while_never": HEAD + "#1 = 5\no1 while [#1 LT 5]\n  G1 X99\no1 endwhile\nG1 X1\nM2\n",
    "do_while": HEAD + "#1 = 3\no3 do\n  G1 Y#1\n  #1 = [#1 - 1]\no3 while [#1 GT 0]\nG1 Z1\nM2\n",
    "repeat": HEAD + "#1 = 0\no4 repeat [3]\n  G1 Z#1\n  #1 = [#1 + 0.5]\no4 endrepeat\n"
    "o5 repeat [0]\n  G1 Z99\no5 endrepeat\nG1 X2\nM2\n",
    "break_continue": HEAD + "#1 = 0\no8 while [#1 LT 10]\n  #1 = [#1 + 1]\n  o9 if [#1 EQ 2]\n    o8 continue\n"
    "  o9 endif\n  o11 if [#1 EQ 5]\n    o8 break\n  o11 endif\n  G1 X#1\no8 endwhile\nG1 Y#1\nM2\n",
    # LinuxCNC's flags: a break leaves doing_break set, so the next do-while runs once
    "break_then_do_quirk": HEAD + "#1 = 0\no1 while [#1 LT 5]\n  #1 = [#1 + 1]\n  o2 if [#1 EQ 3]\n"
    "    o1 break\n  o2 endif\no1 endwhile\no3 do\n  G1 Y#1\n  #1 = [#1 - 1]\no3 while [#1 GT 0]\nG1 Z1\nM2\n",
    "continue_in_do": HEAD + "#1 = 0\no5 do\n  #1 = [#1 + 1]\n  G1 X#1\n  o6 if [#1 EQ 2]\n    o5 continue\n"
    "  o6 endif\n  G1 Z#1\no5 while [#1 LT 4]\nM2\n",
    "recursion": HEAD + "#<_n> = 0\no20 sub\n  #<_n> = [#<_n> + 1]\n  o21 if [#<_n> LT 4]\n    G1 X#<_n>\n"
    "    o20 call\n    G1 Y#<_n>\n  o21 endif\no20 endsub\no20 call\nM2\n",
    "nested_repeat_globals": HEAD + "o10 repeat [2]\n  o11 repeat [3]\n    G91 G1 X1\n  o11 endrepeat\n"
    "  G90 G1 Y[#31 + 1]\n  #31 = [#31 + 1]\no10 endrepeat\nG90\nM2\n",
    "m98_linuxcnc": HEAD + "M98 P300 L2\nM98 P300\nG1 Y#1\nM2\nO300\n#1 = [#1 + 1]\nG91 G1 X1\nG90\nM99\n",
    "comments_kept": HEAD + "#1 = 2 (width)\nG1 X#1 (move to #1) ; trailing\n(plain comment)\nG1 Y1 ; no change\nM2\n",
    "block_delete_word": HEAD + "#1 = 4\n/G1 X#1\nG1 Y2\nM2\n",
    "line_numbers": HEAD + "N10 #1 = 3\nN20 G1 X#1\nN30 G1 Y[#1 * 2]\nN40 M2\n",
    "percent_delimited": "%\n" + HEAD + "#1 = 1\nG1 X#1\n%\n",
    "program_number_top": "O1234\n" + HEAD + "#1 = 1\nG1 X#1\nM2\n",
    "inch": "G20 G17 G90 F10\n#1 = [1 / 3]\nG1 X#1 Y[#1 * 2]\nG2 X[#1 * 3] Y[#1 * 2] I[#1] J0\nM2\n",
}


@requires_rs274
@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_expansion_moves_like_linuxcnc(name):
    text = PROGRAMS[name]
    lines = flat(text)
    out = "".join(sl.text for sl in lines)
    ref, got = run_rs274_many([text, out])
    assert ref.ok, ref.error
    assert ref.motions, "the program must move"
    assert got.ok, got.error + "\n" + out
    assert same_motions(ref.motions, got.motions) == "", out
    # flat: no parameter, expression or control left (comments aside)
    for sl in lines:
        code = re.sub(r"\([^)]*\)|;.*", "", sl.text)
        assert "#" not in code, sl
        assert "[" not in code, sl
        assert not re.match(r"\s*/?\s*(N\d+\s*)?[oO]\s*(\d|<)", code) or sl.original, sl
        if sl.original:
            assert sl.text == split_lines(text)[sl.lineno - 1]


@requires_rs274
def test_subroutine_file_on_path(tmp_path):
    sub = "o<square> sub\n  G1 X#1 Y0\n  G1 X#1 Y#1\n  G1 X0 Y#1\n  G1 X0 Y0\no<square> endsub\nM2\n"
    (tmp_path / "square.ngc").write_text(sub)
    text = HEAD + "o<square> call [5]\no<Square> call [2.5]\nM2\n"
    ref = run_rs274(text, files={"square.ngc": sub})
    assert ref.ok, ref.error
    lines = flat(text, path="main.ngc", subroutine_path=[tmp_path / "missing", tmp_path])
    got = run_rs274("".join(sl.text for sl in lines))
    assert got.ok, got.error
    assert same_motions(ref.motions, got.motions) == ""
    from_sub = [sl for sl in lines if sl.path == str(tmp_path / "square.ngc")]
    assert [sl.lineno for sl in from_sub] == [2, 3, 4, 5] * 2
    assert from_sub[0].text == "  G1 X5.0 Y0\n"
    assert from_sub[4].text == "  G1 X2.5 Y0\n"


@requires_rs274
def test_m98_program_file_on_path(tmp_path):
    body = "G91 G1 X1 Y2\nG90\nM99\n"
    (tmp_path / "O5001.nc").write_text(body)
    text = HEAD + "M98 P5001 L3\nM2\n"
    ref = run_rs274(text, files={"5001.ngc": "O5001\n" + body})
    assert ref.ok, ref.error
    out = flat_text(text, subroutine_path=[tmp_path])
    assert out == HEAD + "G91 G1 X1 Y2\nG90\n" * 3 + "M2\n"
    got = run_rs274(out)
    assert same_motions(ref.motions, got.motions) == ""


def test_rewritten_lines_hand_checked():
    text = "#1 = 2 (w)\n#<d> = [#1 * 0.1]\nG1 X#1  Y[#<d> + 0.2] F#1 ; feed\nG[#1 - 1] X0\nM2\n"
    lines = flat(text)
    assert [(sl.lineno, sl.text, sl.original) for sl in lines] == [
        (3, "G1 X2.0  Y0.4 F2.0 ; feed\n", False),
        (4, "G1 X0\n", False),
        (5, "M2\n", True),
    ]


def test_untouched_lines_keep_their_bytes_and_endings():
    text = "G21\r\n#1 = 1\r\nG1  x1.500 (keep)\r\nG1 X#1\r\nM2"
    lines = flat(text)
    assert [sl.text for sl in lines] == ["G21\r\n", "G1  x1.500 (keep)\r\n", "G1 X1.0\r\n", "M2"]
    assert [sl.original for sl in lines] == [True, True, False, True]


def test_execution_stops_at_m2_and_keeps_closing_percent():
    text = "%\nO0001 (PART)\n#1 = 2\nG1 X#1 F100\nM30\nG1 X9\n%\n"
    lines = flat(text, dialect="fanuc")
    assert [sl.text for sl in lines] == ["%\n", "O0001 (PART)\n", "G1 X2.0 F100\n", "M30\n", "%\n"]


def test_format_number():
    assert format_number(2.0) == "2.0"
    assert format_number(0.1 + 0.2) == "0.3"
    assert format_number(-0.0) == "0.0"
    assert format_number(-1e-13) == "0.0"
    assert format_number(1 / 3) == "0.333333333333"
    assert format_number(1234.5678) == "1234.5678"
    assert format_number(1e-7) == "0.0000001"
    assert format_number(123456789.123) == "123456789.123"
    assert "e" not in format_number(1e20)
    assert format_number(3.0, "M") == "3"
    assert format_number(1000.0, "P") == "1000"
    assert format_number(43.1, "G") == "43.1"
    assert format_number(10.0, "X") == "10.0"


def test_format_number_resolves_a_nanometre():
    rng = __import__("numpy").random.default_rng(11)
    for v in rng.uniform(-2000, 2000, 500):
        assert abs(float(format_number(v)) - v) <= 1e-9


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("G21\nG1 X1 Y2 F100\nM2\n", False),
        ("O1234 (NAME)\nG1 X1\nM30\n%\n", False),
        ("%\n(#1 only in a comment [x])\nG1 X1 ; #2 here too\n%\n", False),
        ("G1 X#1\n", True),
        ("#<a> = 1\n", True),
        ("G1 X[1 + 2]\n", True),
        ("o100 call\n", True),
        ("O<sub> sub\n", True),
        ("M98 P1000\n", True),
        ("G65 P9000 A1\n", True),
        ("IF [#1 EQ 1] GOTO 10\n", True),
        ("WHILE [#1 LT 3] DO 1\n", True),
    ],
)
def test_needs_expansion(text, expected):
    assert needs_expansion(split_lines(text)) is expected


def _raises(text: str, kind=PostprocError, **kw) -> PostprocError:
    with pytest.raises(kind) as err:
        flat(text, **kw)
    return err.value


@pytest.mark.parametrize(
    ("text", "lineno", "col", "words"),
    [
        (HEAD + "G1 X#5061\nM2\n", 2, 5, ["#5061", "probe"]),
        (HEAD + "G1 X1\nG1 Y[#5422 + 1]\nM2\n", 3, 6, ["#5422", "current position"]),
        (HEAD + "G1 Z#5403\n", 2, 5, ["#5403", "tool"]),
        (HEAD + "G1 X#5221\n", 2, 5, ["#5221", "offset"]),
        (HEAD + "G1 X#<_x>\n", 2, 5, ["#<_x>", "live state"]),
        (HEAD + "#<p> = #<_hal[motion.probe-input]>\n", 2, 8, ["_hal[", "live state"]),
        (HEAD + "#5221 = 3\n", 2, 1, ["#5221", "G10"]),
    ],
)
def test_machine_state_is_refused_with_its_place(text, lineno, col, words):
    err = _raises(text, ExpansionError, path="p.ngc")
    assert (err.path, err.lineno, err.col) == ("p.ngc", lineno, col)
    for w in words:
        assert w in str(err)


def test_a_parameter_set_by_the_program_may_be_read():
    assert flat_text(HEAD + "#5070 = 1\nG1 X#5070\nM2\n") == HEAD + "G1 X1.0\nM2\n"


@pytest.mark.parametrize(
    ("text", "lineno", "col", "words"),
    [
        (HEAD + "G1 X#<nope>\n", 2, 5, ["#<nope>", "not defined"]),
        (HEAD + "G1 X[1 / [2 - 2]]\n", 2, 8, ["division by zero"]),
        (HEAD + "G1 X[SQRT[-1]]\n", 2, 6, ["SQRT"]),
        (HEAD + "G1 X[1 + ]\n", 2, 10, ["expected a number"]),
        (HEAD + "G1 X[1 + 2\n", 2, 11, ["']'"]),
        # a named parameter marks the program as LinuxCNC, which takes one value after '='
        (HEAD + "#<x> = 1\n#1 = 2 + 3\n", 3, 8, ["unexpected", "[ ]"]),
        (HEAD + "o<missing> call\nM2\n", 2, 1, ["o<missing>", "not found", "missing.ngc"]),
        (HEAD + "o1 if [0]\nG1 X1\nM2\n", 2, 1, ["'o1 if'", "file ended"]),
        (HEAD + "o1 sub\nG1 X1\nM2\n", 2, 1, ["o1 sub", "endsub"]),
        (HEAD + "o1 endwhile\nM2\n", 2, 1, ["o1 endwhile"]),
        (HEAD + "o3 while [1]\no3 endwhile\n", 3, 1, ["endless loop", "changes nothing"]),
        (HEAD + "G1 X@1\n", 2, 5, ["polar"]),
        # rs274ngc evaluates an elseif condition even after a branch was taken
        (HEAD + "o3 if [1]\nG1 X1\no3 elseif [1/0]\no3 endif\nM2\n", 4, 13, ["division by zero"]),
    ],
)
def test_errors_name_path_line_col(text, lineno, col, words):
    err = _raises(text, path="p.ngc", max_lines=1000)
    assert (err.path, err.lineno, err.col) == ("p.ngc", lineno, col), str(err)
    for w in words:
        assert w in str(err), str(err)


def test_nested_comment_is_an_error_in_linuxcnc_dialect_only():
    text = "G21\n#1 = 1 (a (b) c)\nG1 X#1 F1\nM2\n"
    assert flat_text(text) == "G21\nG1 X1.0 F1\nM2\n"
    err = _raises(text, GcodeSyntaxError, dialect="linuxcnc")
    assert (err.lineno, err.col) == (2, 11)


def test_block_delete_with_a_setting_is_refused():
    err = _raises(HEAD + "/#1 = 3\nM2\n", ExpansionError)
    assert err.lineno == 2
    assert "block-delete" in str(err)


def test_recursion_is_stopped():
    err = _raises(HEAD + "o1 sub\n  o1 call\no1 endsub\no1 call\nM2\n", ExpansionError)
    assert "nested deeper" in str(err)


def test_byte_order_mark_on_the_first_line():
    lines = flat("\ufeff#1 = 2\nG1 X#1 F1\nM2\n")
    assert [sl.text for sl in lines] == ["G1 X2.0 F1\n", "M2\n"]
    assert flat("\ufeffG21\nM2\n")[0].text == "\ufeffG21\n"
