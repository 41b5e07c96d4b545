"""A Sinumerik program's control flow executed into a flat program.

SINUMERIK 840D sl Programming Manual Job planning, "Flexible NC programming": "Program
jumps and branches" (labels ``NAME:``, ``GOTOF``/``GOTOB``/``GOTO``/``GOTOC``, ``IF cond
GOTOF label``), "Program section repetitions" (``REPEAT label P=n``, ``REPEAT label1 label2
P=n``, ``REPEATB label P=n``: the section is repeated n times after it has run once, then
the program goes on after the REPEAT block) and "Control structures" (``IF``/``ELSE``/
``ENDIF``, ``WHILE``/``ENDWHILE``, ``LOOP``/``ENDLOOP``, ``FOR var = a TO b``/``ENDFOR``,
``REPEAT``/``UNTIL``) and the branch ``CASE (expr) OF 1 GOTOF A ... DEFAULT GOTOF B``.
Conditions compare expressions with ``== <> < > <= >=`` joined by
``AND``, ``OR``, ``NOT``.

Every other line is yielded as it is (``original``), in the order the controller runs it;
a control line is left out; a label before a block's words is cut from it. The R
parameters and DEF variables a condition reads are those the lines run so far have set
(read with :mod:`postproc.gcode.sinumerik`'s reader, as the interpreter reads them again).
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from postproc.errors import GcodeSyntaxError, UnsupportedGcodeError
from postproc.gcode import sinumerik

_LABEL = re.compile(r"^(\s*(?:N\d+\s+)?)([A-Za-z_][A-Za-z0-9_]*):(?!=)\s*")
_BLOCK_NO = re.compile(r"^\s*(?:N\d+\s*)?", re.I)
_KEYWORD = re.compile(r"(?i)(IF|ELSE|ENDIF|WHILE|ENDWHILE|LOOP|ENDLOOP|FOR|ENDFOR|REPEATB|REPEAT|UNTIL|"
                      r"GOTOF|GOTOB|GOTOC|GOTO|CASE)\b")
_JUMP = re.compile(r"(?i)\b(GOTOF|GOTOB|GOTOC|GOTO)\s+([A-Za-z_][A-Za-z0-9_]*)\s*$")
_FOR = re.compile(r"(?i)^([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.+?)\s+TO\s+(.+)$")
_REPEAT = re.compile(r"(?i)^([A-Za-z_][A-Za-z0-9_]*)(?:\s+([A-Za-z_][A-Za-z0-9_]*))?(?:\s+P\s*=\s*(.+))?$")
_COMPARE = ("==", "<>", "<=", ">=", "<", ">")
#: CASE (expression) OF constant GOTOF label ... DEFAULT GOTOF label: the OF, each branch, DEFAULT
_CASE_OF = re.compile(r"(?i)\bOF\b")
_CASE_BRANCH = re.compile(r"(?i)\s*(DEFAULT|[+-]?\d+(?:\.\d*)?)\s*(GOTOF|GOTOB|GOTOC|GOTO)\s+([A-Za-z_]\w*)\s*")


#: subprogram nesting (Job planning, "Subprogram technique": up to 16 levels with the main program)
MAX_CALL_DEPTH = 16
_L_CALL = re.compile(r"(?i)^\s*(?:N\d+\s+)?L(\d+)(?:\s+P\s*=?\s*(\d+))?\s*$")
_NAME_CALL = re.compile(r"(?i)^\s*(?:N\d+\s+)?(?:CALL\s+\"([A-Za-z_]\w*)\"|([A-Za-z_]\w*)\s*(?:\((.*)\))?)"
                        r"(?:\s+P\s*=?\s*(\d+))?\s*$")
_PROC = re.compile(r"(?i)^\s*(?:N\d+\s+)?PROC\s+([A-Za-z_]\w*)\s*(?:\((.*?)\))?\s*(.*)$")
_EXTERN = re.compile(r"(?i)^\s*(?:N\d+\s+)?EXTERN\s+([A-Za-z_]\w*)")
_RETURN = re.compile(r"(?i)\bM0*17\b|\bRET\b")
_DEF_NAMES = re.compile(r"(?i)^\s*(?:N\d+\s+)?DEF\s+\w+\s+(.*)$")


@dataclass
class _Shared:
    """What every level of the program shares: the variables, the blocks run, where the
    subprograms are, the names EXTERN declared."""

    env: dict[str, float]
    max_lines: int
    subroutine_path: tuple[Path, ...]
    executed: int = 0
    externs: set[str] | None = None
    depth: int = 0


class _End(Exception):
    """M2/M30 in a subprogram: the end of the whole program."""


@dataclass
class _Repeat:
    start: int  # first line of the section
    end: int  # last line of the section
    back: int  # the line after the REPEAT block
    left: int  # repetitions still to run


class SinumerikExpander:
    def __init__(self, lines: Sequence[str], path: str | None, shared: _Shared, sub: bool = False) -> None:
        self.lines = list(lines)
        self.path = path
        self.shared = shared
        self.max_lines = shared.max_lines
        self.env = shared.env
        self.sub = sub  # a subprogram: M17/RET return to the caller
        self.current_path = path  # the file of the line last yielded (a subprogram's while it runs)
        self.codes = [sinumerik.code_of(ln) for ln in self.lines]
        self.labels: dict[str, int] = {}
        self.statements: list[tuple[str, str, int] | None] = []  # (keyword, rest, col) per line
        for k, code in enumerate(self.codes):
            m = _LABEL.match(code)
            if m and m.group(2).upper() not in sinumerik.FRAME_KEYWORDS:
                self.labels.setdefault(m.group(2).upper(), k)
                code = code[:m.start(2)] + " " * (m.end() - m.start(2)) + code[m.end():]
            start = _BLOCK_NO.match(code).end()  # type: ignore[union-attr]
            km = _KEYWORD.match(code, start)
            self.statements.append((km.group(1).upper(), code[km.end():].strip(), start + 1) if km else None)
        self.pairs = self._pair()
        self.set_lines: list[str] = []  # assignments a control line makes (FOR's variable), to yield

    def error(self, k: int, col: int, msg: str, cls: type = GcodeSyntaxError) -> GcodeSyntaxError:
        return cls(f"Sinumerik {msg}", path=self.path, lineno=k + 1, col=col)

    def _pair(self) -> dict[int, int]:
        """The matching lines of IF/ELSE/ENDIF, WHILE/ENDWHILE, LOOP/ENDLOOP, FOR/ENDFOR and
        REPEAT/UNTIL (a REPEAT without labels), both ways; ELSE to its ENDIF and IF to ELSE."""
        opens = {"IF": "ENDIF", "WHILE": "ENDWHILE", "LOOP": "ENDLOOP", "FOR": "ENDFOR", "REPEAT": "UNTIL"}
        stack: list[tuple[str, int]] = []
        pairs: dict[int, int] = {}
        for k, st in enumerate(self.statements):
            if st is None:
                continue
            kw, rest, col = st
            if kw == "IF" and _JUMP.search(rest):
                continue  # IF cond GOTOF label: one block
            if kw == "REPEAT" and rest:
                continue  # REPEAT label P=n: a section repetition
            if kw in opens:
                stack.append((kw, k))
            elif kw == "ELSE":
                if not stack or stack[-1][0] != "IF":
                    raise self.error(k, col, "ELSE without its IF")
                pairs[stack[-1][1]] = k
                stack[-1] = ("ELSE", k)
            elif kw in opens.values() or kw == "ENDIF":
                want = next(o for o, c in opens.items() if c == kw)
                if not stack or stack[-1][0] not in ((want, "ELSE") if want == "IF" else (want,)):
                    raise self.error(k, col, f"{kw} without its {want}")
                _o, j = stack.pop()
                pairs[j] = k
                pairs[k] = j
        if stack:
            kw, j = stack[-1]
            raise self.error(j, 1, f"{kw} without its {opens.get(kw, 'ENDIF')}")
        return pairs

    # -- values ----------------------------------------------------------------------------
    def value(self, text: str, k: int) -> float:
        r = sinumerik.BlockReader(text, self.path, k + 1, self.env)
        v, e = r.expression_at(0, True)
        if r.code[e:].strip():
            raise self.error(k, 1, f"unexpected {r.code[e:].strip()!r} in the expression {text!r}")
        return v

    def condition(self, text: str, k: int) -> bool:
        """``a == b``, ``a < b AND NOT c > d``, ...: evaluated left to right, AND before OR."""
        ors = re.split(r"(?i)\s+OR\s+", text)
        return any(all(self._compare(part, k) for part in re.split(r"(?i)\s+AND\s+", o)) for o in ors)

    def _compare(self, text: str, k: int) -> bool:
        text = text.strip()
        m = re.match(r"(?i)NOT\s+(.*)$", text)
        if m:
            return not self._compare(m.group(1), k)
        depth = 0
        for j, c in enumerate(text):
            depth += c == "("
            depth -= c == ")"
            if depth == 0:
                for op in _COMPARE:
                    if text.startswith(op, j):
                        a, b = self.value(text[:j], k), self.value(text[j + len(op):], k)
                        return {"==": a == b, "<>": a != b, "<=": a <= b, ">=": a >= b, "<": a < b,
                                ">": a > b}[op]
        if text.startswith("(") and text.endswith(")"):
            return self.condition(text[1:-1], k)
        return self.value(text, k) != 0.0

    def jump(self, k: int, how: str, label: str, col: int) -> int | None:
        """The line a GOTOF/GOTOB/GOTO/GOTOC from line ``k`` goes to (None: GOTOC not found)."""
        target = self.labels.get(label.upper())
        forward = target is not None and target > k
        if target is None or (how == "GOTOF" and not forward) or (how == "GOTOB" and forward):
            if how == "GOTOC":
                return None
            raise self.error(k, col, f"{how} {label}: jump label not found "
                             f"{'after' if how == 'GOTOF' else 'before' if how == 'GOTOB' else 'in'} the program")
        return target

    # -- execution ---------------------------------------------------------------------------
    def run(self) -> Iterator[tuple[int, str, bool]]:  # noqa: C901 - one statement per branch
        """``(line index, text, original)`` of every line run, in order."""
        k = 0
        repeats: list[_Repeat] = []
        fors: dict[int, float] = {}  # FOR line -> end value
        n = len(self.lines)
        while k < n:
            self.shared.executed += 1
            if self.shared.executed > self.max_lines:
                raise self.error(k, 1, f"program runs more than {self.max_lines} blocks: an endless loop, or "
                                 "raise the bound", UnsupportedGcodeError)
            st = self.statements[k]
            nxt: int | None = k + 1
            call = self._call_of(k) if st is None else None
            if call is not None:
                yield from self._call(k, *call)
            elif st is None:
                line, original = self._text(k)
                if self.sub and _RETURN.search(self.codes[k]):
                    rest = _RETURN.sub(lambda m: " " * len(m.group()), self.codes[k])
                    if rest.strip() and not re.fullmatch(r"(?i)\s*N\d+\s*", rest):
                        raise self.error(k, 1, "M17/RET with other words in its block (not read)",
                                         UnsupportedGcodeError)
                    yield k, ";" + self.lines[k], False  # the return, as a comment
                    return
                if _EXTERN.match(self.codes[k]) or _PROC.match(self.codes[k]):
                    self.shared.externs = (self.shared.externs or set()) | {m.group(1).upper() for m in
                                                                             [_EXTERN.match(self.codes[k])] if m}
                    yield k, ";" + self.lines[k], False  # a declaration: kept as a comment
                elif line is not None:
                    try:
                        sinumerik.read_block(line, self.path, k + 1, self.env)  # the variables it sets
                    except UnsupportedGcodeError:
                        pass  # the interpreter refuses it in its words when it reads the line
                    yield k, line, original
                    if self._ends(line):
                        if self.sub:
                            raise _End
                        return
            else:
                kw, rest, col = st
                nxt = self._statement(k, kw, rest, col, repeats, fors)
                for text in self.set_lines:
                    yield k, text, False
                self.set_lines.clear()
                if nxt is None:
                    nxt = k + 1
            while repeats and k == repeats[-1].end and nxt == k + 1:
                r = repeats[-1]
                r.left -= 1
                if r.left > 0:
                    nxt = r.start
                    break
                repeats.pop()
                nxt = r.back
            k = nxt if nxt is not None else k + 1

    def _call_of(self, k: int) -> tuple[str, list[str], int, int] | None:
        """``(name, argument texts, repeats, column)`` when line ``k`` calls a subprogram."""
        code = self.codes[k]
        m = _L_CALL.match(code)
        if m:
            return f"L{m.group(1)}", [], int(m.group(2) or 1), code.upper().index("L") + 1
        m = _NAME_CALL.match(self.lines[k][:sinumerik.code_end(self.lines[k])])  # CALL "NAME": the string kept
        if not m:
            return None
        name = (m.group(1) or m.group(2)).upper()
        known = (name in (self.shared.externs or set()) or m.group(1) is not None
                 or self._file(name) is not None)
        if not known or name in sinumerik.KEPT_KEYWORDS or name in sinumerik.FRAME_KEYWORDS or name in self.env:
            return None
        return name, _parse_args(m.group(3)) if m.group(3) else [], int(m.group(4) or 1), 1


    def _file(self, name: str) -> Path | None:
        where = ([Path(self.path).parent] if self.path else []) + list(self.shared.subroutine_path)
        return _find(name, where)


    def _call(self, k: int, name: str, args: list[str], repeats: int,
              col: int) -> Iterator[tuple[int, str, bool]]:
        """Run the subprogram ``name`` ``repeats`` times: its PROC parameters set by value (written
        as DEF lines), its local variables given back their caller's values on return."""
        f = self._file(name)
        if f is None:
            raise self.error(k, col, f"{name}: subprogram call, {name}.SPF not found beside the program or on "
                             "--subroutine-path", UnsupportedGcodeError)
        if self.shared.depth + 1 >= MAX_CALL_DEPTH:
            raise self.error(k, col, f"{name}: subprograms nested deeper than {MAX_CALL_DEPTH} levels",
                             UnsupportedGcodeError)
        values: list[float | None] = [None if not a else self.value(a, k) for a in args]
        from postproc.gcode.lexer import split_lines

        lines = split_lines(f.read_text(encoding="utf-8", errors="replace"))
        sub = SinumerikExpander(lines, str(f), self.shared, sub=True)
        params: list[tuple[str, str]] = []
        for j, code in enumerate(sub.codes):
            m = _PROC.match(code)
            if m:
                if re.search(r"(?i)\bSAVE\b", m.group(3) or ""):
                    raise sub.error(j, 1, f"PROC {m.group(1)} SAVE (the caller's G codes restored on return: not read)",
                                    UnsupportedGcodeError)
                for p in _parse_args(m.group(2)) if m.group(2) else []:
                    pm = re.fullmatch(r"(?i)(VAR\s+)?(REAL|INT|BOOL)\s+([A-Za-z_]\w*)(?:\s*=\s*(.+))?", p)
                    if not pm or pm.group(1):
                        raise sub.error(j, 1, f"PROC parameter {p!r} (REAL, INT or BOOL by value are read)",
                                        UnsupportedGcodeError)
                    params.append((pm.group(2).upper(), pm.group(3).upper()))
                break
        if len(values) > len(params):
            raise self.error(k, col, f"{name}: {len(values)} arguments for {len(params)} parameters")
        ending = self.lines[k][len(self.lines[k].rstrip("\r\n")):] or "\n"
        yield k, ";" + self.lines[k], False  # the call, as a comment
        for _ in range(repeats):
            before = dict(self.env)
            self.shared.depth += 1
            for i, (kind_name, pname) in enumerate(params):
                given = values[i] if i < len(values) else None
                v = given if given is not None else 0.0
                self.env[pname] = v
                yield k, f"DEF {kind_name} {pname}={sinumerik.number_text(v)}{ending}", False
            local = {n for _t, n in params}
            try:
                for j, text, original in sub.run():
                    m = _DEF_NAMES.match(sub.codes[j])
                    if m:
                        local |= {re.split(r"[=\s\[]", n.strip())[0].upper() for n in m.group(1).split(",")}
                    self.current_path = sub.current_path
                    yield j, text, original
                    self.current_path = self.path
            finally:
                self.shared.depth -= 1
                self.current_path = self.path
            for n in sorted(local):
                if n in before:
                    self.env[n] = before[n]
                    yield k, f"{n}={sinumerik.number_text(before[n])}{ending}", False
                else:
                    self.env.pop(n, None)

    @staticmethod
    def _ends(line: str) -> bool:
        """M2, M17, M30 or RET: the end of the program (what follows is not run)."""
        return re.search(r"(?i)\bM0*(?:2|17|30)\b|\bRET\b", sinumerik.code_of(line)) is not None

    def _text(self, k: int) -> tuple[str | None, bool]:
        line = self.lines[k]
        if self.sub and line.lstrip().startswith("%"):
            return ";" + line, False  # a subprogram's %_N_..._SPF file header, inside the flat program
        m = _LABEL.match(self.codes[k])
        if not m or m.group(2).upper() in sinumerik.FRAME_KEYWORDS:
            return line, True
        rest = line[:m.start(2)] + line[m.end():]
        if not sinumerik.code_of(rest).strip() or not rest.strip():
            return ";" + line, False  # a label alone: kept as a comment
        return rest, False

    def _assigned(self, k: int, name: str) -> None:
        """Write the value a control line gave ``name`` as an assignment of the flat program
        (the interpreter reads the variable there)."""
        ending = self.lines[k][len(self.lines[k].rstrip("\r\n")):] or "\n"
        self.set_lines.append(f"{name}={sinumerik.number_text(self.env[name])}{ending}")

    def _statement(self, k: int, kw: str, rest: str, col: int, repeats: list[_Repeat],  # noqa: C901
                   fors: dict[int, float]) -> int | None:
        pairs = self.pairs
        if kw in ("GOTOF", "GOTOB", "GOTO", "GOTOC"):
            return self.jump(k, kw, rest.split()[0] if rest else "", col)
        if kw == "IF":
            jm = _JUMP.search(rest)
            if jm:
                if self.condition(rest[:jm.start()], k):
                    return self.jump(k, jm.group(1).upper(), jm.group(2), col)
                return None
            if self.condition(rest, k):
                return None
            end = pairs[k]
            return end + 1  # to the block after ELSE, or after ENDIF
        if kw == "ELSE":
            return pairs[k] + 1  # the IF part ran: past ENDIF
        if kw in ("ENDIF", "LOOP"):
            return None
        if kw == "WHILE":
            return None if self.condition(rest, k) else pairs[k] + 1
        if kw == "ENDWHILE":
            return pairs[k]
        if kw == "ENDLOOP":
            return pairs[k]
        if kw == "FOR":
            m = _FOR.match(rest)
            if not m:
                raise self.error(k, col, "FOR without 'variable = start TO end'")
            name = m.group(1).upper()
            if name not in self.env:
                raise self.error(k, col, f"FOR variable {name} is not defined (DEF INT {name})")
            self.env[name] = self.value(m.group(2), k)
            fors[k] = self.value(m.group(3), k)
            self._assigned(k, name)
            return None if self.env[name] <= fors[k] else pairs[k] + 1
        if kw == "ENDFOR":
            j = pairs[k]
            m = _FOR.match(self.statements[j][1])  # type: ignore[index]
            name = m.group(1).upper()  # type: ignore[union-attr]
            self.env[name] += 1
            self._assigned(k, name)
            return j + 1 if self.env[name] <= fors[j] else None
        if kw == "CASE":
            return self._case(k, rest, col)
        if kw == "REPEAT" and not rest:
            return None
        if kw == "UNTIL":
            return None if self.condition(rest, k) else pairs[k] + 1
        if kw in ("REPEAT", "REPEATB"):
            m = _REPEAT.match(rest)
            if not m:
                raise self.error(k, col, f"{kw} {rest}: not 'label [label] P=n'")
            count = round(self.value(m.group(3), k)) if m.group(3) else 1
            start = self.labels.get(m.group(1).upper())
            if start is None:
                raise self.error(k, col, f"{kw} {m.group(1)}: jump label not found")
            if kw == "REPEATB":
                end = start
            elif m.group(2):
                end = self.labels.get(m.group(2).upper(), -1)
                if end < start:
                    raise self.error(k, col, f"REPEAT {m.group(1)} {m.group(2)}: end label not found after the first")
            else:
                end = k - 1
                if start >= k:
                    raise self.error(k, col, f"REPEAT {m.group(1)}: the label must come before the REPEAT")
            if count <= 0:
                return None
            repeats.append(_Repeat(start, end, k + 1, count))
            return start
        raise self.error(k, col, f"{kw} (not read by postproc)", UnsupportedGcodeError)


    def _case(self, k: int, rest: str, col: int) -> int | None:
        """``CASE (expression) OF 1 GOTOF A 2 GOTOF B DEFAULT GOTOF C`` (Job planning, "Program
        branch (CASE ... OF ... DEFAULT ...)"): the jump of the first constant equal to the
        expression's value, else DEFAULT's, else the next block."""
        of = _CASE_OF.search(rest)
        if of is None:
            raise self.error(k, col, "CASE without OF")
        value = self.value(rest[:of.start()], k)
        branches, j = [], of.end()
        while j < len(rest):
            m = _CASE_BRANCH.match(rest, j)
            if m is None:
                raise self.error(k, col, f"CASE branch {rest[j:].strip()!r} (only number constants, each with "
                                 "GOTOF/GOTOB/GOTO/GOTOC and a label, are read)", UnsupportedGcodeError)
            branches.append(m.groups())
            j = m.end()
        for constant, how, label in branches:
            if constant.upper() != "DEFAULT" and float(constant) == value:
                return self.jump(k, how.upper(), label, col)
        for constant, how, label in branches:
            if constant.upper() == "DEFAULT":
                return self.jump(k, how.upper(), label, col)
        return None


def expand_sinumerik(lines: Sequence[str], path: str | None, max_lines: int,
                     subroutine_path: Sequence[Path] = ()) -> Iterator[tuple[int, str | None, str, bool]]:
    """The flat program of ``lines``: ``(line index, file, text, original)`` per line run
    (the file: ``path`` or a subprogram's)."""
    shared = _Shared({}, max_lines, tuple(Path(p) for p in subroutine_path))
    ex = SinumerikExpander(lines, path, shared)
    try:
        for k, text, original in ex.run():
            yield k, ex.current_path, text, original
    except _End:
        return


# -- subprograms (Job planning, "Subprogram technique": L<n>, a name, CALL, PROC, M17/RET) ------
def _parse_args(text: str) -> list[str]:
    """A call's arguments as texts (commas inside parentheses kept)."""
    out, depth, cur = [], 0, ""
    for c in text:
        if c == "," and depth == 0:
            out.append(cur)
            cur = ""
            continue
        depth += (c == "(") - (c == ")")
        cur += c
    out.append(cur)
    return [a.strip() for a in out]


def _find(name: str, where: Sequence[Path]) -> Path | None:
    for d in where:
        try:
            for f in sorted(d.iterdir()):
                if f.stem.upper() in (name.upper(), f"_N_{name.upper()}_SPF") and f.suffix.upper() in (".SPF", ".MPF"):
                    return f
        except OSError:
            continue
    return None


