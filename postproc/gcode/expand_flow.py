"""Loops, branches and o-words of the expansion: Fanuc macro B (IF GOTO, IF THEN,
WHILE DO END) and LinuxCNC o-word control (sub/endsub/call/return, do/while, repeat,
if/elseif/else, break/continue), executed as ``interp_o_word.cc`` does."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

from postproc.gcode.expand_calls import Calls
from postproc.gcode.expand_state import (
    LINUXCNC_SUB_PARAMS,
    MAX_CALL_DEPTH,
    CallFrame,
    OwordPlace,
    oname,
)
from postproc.gcode.expand_syntax import (
    Block,
    Macro,
    OWord,
    Word,
)
from postproc.gcode.expr import (
    NULL,
    to_index,
)


class Flow(Calls):
    # -- Fanuc macro statements -------------------------------------------------
    def _macro(self, b: Block, m: Macro) -> None:
        """Run the macro statement ``m`` (``b.macro``) of block ``b``."""
        if b.slash:
            raise self.refuse(1, "a macro statement on a block-delete ('/') line")
        if m.kind == "goto" or (m.kind == "if_goto" and self._cond(m)):
            self.idx = self._sequence(self.unit_cur, self._target(m), self.cur_idx + 1, m.col)
            if self.idx <= self.cur_idx:  # a jump back: one more pass of a loop
                self.count_iteration(m.col)
                self._another_pass(m.col)
        elif m.kind == "if_then":
            if self._cond(m):
                a = m.assign
                if a is None:  # pragma: no cover - the parser sets it
                    raise AssertionError("IF .. THEN without its setting")
                v = self._value(a.node)
                self.pending = []
                self._queue_setting(a, v)
                self._apply_pending()
        elif m.kind in ("while", "do"):
            end = self._loop_end_of(m)
            if m.kind == "while" and not self._cond(m):
                self.idx = end + 1
        elif m.kind == "end":
            self.count_iteration(m.col)
            self._another_pass(m.col)
            self.idx = self._find_do(m.loop, m.col)

    def _cond(self, m: Macro) -> bool:
        """Is the condition of IF or WHILE statement ``m`` true?"""
        if m.cond is None:  # pragma: no cover - the parser sets it
            raise AssertionError(f"{m.kind} statement without its condition")
        v = self._value(m.cond)
        return v is not NULL and v != 0.0

    def _target(self, m: Macro) -> int:
        if m.target is None:  # pragma: no cover - the parser sets it
            raise AssertionError(f"{m.kind} statement without its target")
        v = self._value(m.target)
        if v is NULL:
            raise self.error(m.col, "GOTO to a vacant variable")
        return to_index(self, v, m.col)

    def _loop_end_of(self, m: Macro) -> int:
        """The line of the END that closes the WHILE/DO ``m`` on the line running, found
        once: a DO without its END is refused when it first runs, whether or not the loop
        would reach it (Fanuc alarm PS0126: DO and END are not paired), and not only when
        its condition fails."""
        key = (id(self.unit_cur), self.cur_idx)
        end = self._loop_ends.get(key)
        if end is None:
            end = self._loop_ends[key] = self._find_end(m.loop, m.col)
        return end

    def _find_end(self, loop: int, col: int) -> int:
        unit = self.unit_cur
        for k in range(self.cur_idx + 1, len(unit.lines)):
            if "end" in unit.lines[k].lower() or "END" in unit.lines[k]:
                b = unit.block(k)
                if b.macro is not None and b.macro.kind == "end" and b.macro.loop == loop:
                    return k
        raise self.error(col, f"DO {loop} has no END {loop} after it: DO and END must be paired (Fanuc alarm "
                         "PS0126)", hint=f"close the loop with END {loop}")

    def _find_do(self, loop: int, col: int) -> int:
        unit = self.unit_cur
        for k in range(self.cur_idx - 1, -1, -1):
            if "do" in unit.lines[k].lower():
                b = unit.block(k)
                if b.macro is not None and b.macro.kind in ("while", "do") and b.macro.loop == loop:
                    return k
        raise self.error(col, f"END {loop} has no DO {loop} before it")

    # -- LinuxCNC o-words (interp_o_word.cc) ------------------------------------
    def _save_offset(self, ow: OWord) -> None:
        have = self.offsets.get(ow.name)
        if have is not None:
            raise self.error(ow.col, f"o-word o{oname(ow.name)} is already defined at "
                             f"{have.unit.path or '<input>'}:{have.idx + 1}",
                             hint="give each sub, loop and if its own o-number")
        self.offsets[ow.name] = OwordPlace(self.unit_cur, self.cur_idx, ow.kw)
        self.version += 1

    def _check_label(self, ow: OWord, allow_do: bool = False) -> OwordPlace | None:
        op = self.offsets.get(ow.name)
        if op is not None:
            if allow_do and op.kind == "do":
                return op
            if not (op.unit is self.unit_cur and op.idx == self.cur_idx):
                raise self.error(ow.col, f"duplicate o-word label o{oname(ow.name)}: already used at line "
                                 f"{op.idx + 1}", hint="give each sub, loop and if its own o-number")
        return op

    def _need(self, ow: OWord, kinds: tuple[str, ...], what: str) -> OwordPlace:
        op = self.offsets.get(ow.name)
        if op is None:
            raise self.error(ow.col, f"'o{oname(ow.name)} {ow.kw}' without its {what}")
        if op.kind not in kinds:
            raise self.error(ow.col, f"'o{oname(ow.name)} {ow.kw}' does not match 'o{oname(ow.name)} "
                             f"{op.kind}' at line {op.idx + 1}")
        return op

    def _back_to(self, name: str, col: int) -> None:
        """Back to the start of loop ``name`` (from the o-word at column ``col``): one more pass."""
        self.count_iteration(col)
        self._another_pass(col)
        op = self.offsets[name]
        self.unit, self.idx = op.unit, op.idx

    def _skip_block(self, name: str) -> None:
        """Skip the lines up to the o-word line ``name`` that ends the block begun here."""
        self.skipping_o = name
        self.skip_from = (self.unit_cur, self.cur_idx)

    def _label(self, ow: OWord, allow_do: bool = False) -> OwordPlace:
        """The position of the loop or if ``ow`` begins, recorded the first time it runs."""
        op = self._check_label(ow, allow_do)
        if op is None:
            self._save_offset(ow)
            op = self.offsets[ow.name]
        return op

    def _oword(self, b: Block, ow: OWord) -> None:
        """Run the o-word statement ``ow`` (``b.oword``) of block ``b``."""
        if b.slash:
            raise self.refuse(ow.col, "an o-word on a block-delete ('/') line")
        if b.items:
            w = b.items[0]
            if not (isinstance(w, Word) and w.letter == "N" and len(b.items) == 1):
                raise self.error(ow.col, "an o-word line holds nothing but the o-word (and a line number)")
        if self.fanuc:
            raise self.error(ow.col, "o-word control is LinuxCNC syntax",
                             hint="choose --dialect linuxcnc for this program")
        if self.defining_sub is not None and self.skipping_o == self.defining_sub and not (
                ow.name == self.defining_sub and ow.kw == "endsub"):
            return  # inside a definition met in sequence: only its endsub counts
        self._OWORD_HANDLERS[ow.kw](self, ow)

    def _end_skip_at(self, ow: OWord) -> None:
        """A sub or bare o-number line ends the skip to it, and records its position."""
        if self.skipping_o is not None:
            if self.offsets.get(ow.name) is None:
                self.offsets[ow.name] = OwordPlace(self.unit_cur, self.cur_idx, ow.kw)
                self.version += 1
            self.skipping_o = None
        self.skipping_to_sub = None

    def _o_number(self, ow: OWord) -> None:
        """``o100`` alone (a Fanuc-style O number): execution continues into it."""
        self._end_skip_at(ow)

    def _o_sub(self, ow: OWord) -> None:
        self._end_skip_at(ow)
        fr = self.frames[-1]
        if len(self.frames) > 1 and fr.call_type == "oword" and fr.sub_name == ow.name:
            return  # the called subroutine starts here
        if self.defining_sub is not None:
            raise self.error(ow.col, "a subroutine defined inside another subroutine definition")
        # a definition met in sequence: skipped up to its endsub
        self._save_offset(ow)
        self._skip_block(ow.name)
        self.defining_sub = ow.name

    def _o_return(self, ow: OWord) -> None:
        """``endsub`` or ``return [value]``."""
        name, kw = ow.name, ow.kw
        if self.defining_sub == name:
            if kw == "endsub":  # end of a definition met in sequence
                self.skipping_o = None
                self.defining_sub = None
            return
        if len(self.frames) == 1:
            raise self.error(ow.col, f"'o{oname(name)} {kw}' outside a subroutine")
        fr = self.frames[-1]
        if fr.call_type != "oword":
            raise self.error(ow.col, f"'o{oname(name)} {kw}' in a subprogram called with M98",
                             hint="end an M98 subprogram with M99")
        if kw == "endsub" and self.skipping_o is not None:
            self.skipping_o = None
        if ow.args:
            self.globals["_value"] = self._num(ow.args[0], ow.col)
            self.globals["_value_returned"] = 1.0
        for k, v in enumerate(fr.saved or []):
            self.params[k + 1] = v
        self.version += 1
        self._leave(fr)

    def _o_do(self, ow: OWord) -> None:
        self.skipping_o = None
        if ow.name not in self.offsets:
            self._save_offset(ow)

    def _o_repeat(self, ow: OWord) -> None:
        op = self._label(ow)
        self.skipping_o = None
        self.version += 1
        if op.repeat_count == -1:
            op.repeat_count = _round_to_int(self._num(ow.args[0], ow.col))
            self.will_repeat(op.repeat_count, ow.col)
        if op.repeat_count > 0:
            op.repeat_count -= 1
        else:
            self._skip_block(ow.name)
            op.repeat_count = -1

    def _o_while(self, ow: OWord) -> None:
        """``while [test]``: the start of a while loop, or the end of a do loop."""
        op = self._label(ow, allow_do=True)
        self.skipping_o = None
        test = self._num(ow.args[0], ow.col)
        if op.kind == "while":
            if test == 0.0:
                self._skip_block(ow.name)
        elif test != 0.0 and not self.doing_break:  # end of a do loop
            self._back_to(ow.name, ow.col)
        else:
            self.doing_break = False

    def _o_if(self, ow: OWord) -> None:
        self._label(ow)
        if self._num(ow.args[0], ow.col) != 0.0:
            self.skipping_o = None
            self.executed_if = True
        else:
            self._skip_block(ow.name)
            self.executed_if = False

    def _o_elseif(self, ow: OWord) -> None:
        self._need(ow, ("if",), "'if'")
        test = self._num(ow.args[0], ow.col)  # rs274ngc reads (evaluates) it in any case
        if self.executed_if:
            self._skip_block(ow.name)
        elif test != 0.0:
            self.skipping_o = None
            self.executed_if = True

    def _o_else(self, ow: OWord) -> None:
        self._need(ow, ("if",), "'if'")
        if self.executed_if:
            self._skip_block(ow.name)
        elif self.skipping_o == ow.name:
            self.executed_if = True
            self.skipping_o = None

    def _o_endif(self, ow: OWord) -> None:
        self._need(ow, ("if",), "'if'")
        self.skipping_o = None
        self.executed_if = True

    def _o_break(self, ow: OWord) -> None:
        self._need(ow, ("while", "do"), "loop")
        self._skip_block(ow.name)
        self.doing_break = True

    def _o_continue(self, ow: OWord) -> None:
        self._need(ow, ("while", "do"), "loop")
        if self.skipping_o == ow.name:
            return
        self._skip_block(ow.name)
        self.doing_continue = True

    def _o_endwhile(self, ow: OWord) -> None:
        self._need(ow, ("while",), "loop start")
        self._loop_end(ow.name, ow.col)

    def _o_endrepeat(self, ow: OWord) -> None:
        self._need(ow, ("repeat",), "loop start")
        self._loop_end(ow.name, ow.col)

    def _loop_end(self, name: str, col: int) -> None:
        """``endwhile``/``endrepeat``: back to the loop's start, unless the loop is being
        left (its skip ends here) or a continue skipped to here."""
        if self.skipping_o == name:
            self.skipping_o = None
            if self.doing_continue:
                self.doing_continue = False
                self._back_to(name, col)
            return
        self._back_to(name, col)

    def _ocall(self, ow: OWord) -> None:
        args = [self._num(a, ow.col) for a in ow.args]
        if len(args) > LINUXCNC_SUB_PARAMS:
            raise self.error(ow.col, f"more than {LINUXCNC_SUB_PARAMS} call arguments")
        if len(self.frames) > MAX_CALL_DEPTH:
            raise self.refuse(ow.col, f"o-word calls nested deeper than {MAX_CALL_DEPTH} levels",
                              hint="check for a subroutine that calls itself without end")
        saved = [self.params.get(k, 0.0) for k in range(1, LINUXCNC_SUB_PARAMS + 1)]
        for k in range(1, LINUXCNC_SUB_PARAMS + 1):
            self.params[k] = args[k - 1] if k <= len(args) else 0.0
        self.globals["_value"] = 0.0
        self.globals["_value_returned"] = 0.0
        self.version += 1
        self.count_iteration(ow.col)
        fr = CallFrame(call_type="oword", ret_unit=self.unit_cur, ret_idx=self.cur_idx + 1, saved=saved,
                    sub_name=ow.name, call_lineno=self.cur_idx + 1, call_path=self.unit_cur.path)
        self.frames.append(fr)
        op = self.offsets.get(ow.name)
        if op is not None:
            if op.kind != "sub":
                raise self.error(ow.col, f"o{oname(ow.name)} is a '{op.kind}', not a subroutine")
            self.unit, self.idx = op.unit, op.idx + 1
            return
        if _leaves_folder(ow.name):
            raise self.refuse(ow.col, f"subroutine name <{ow.name}> names a path: subroutines are looked up by "
                              "name in the --subroutine-path folders only",
                              hint="call it by its file name without folders, and put the folder on "
                              "--subroutine-path")
        f = self.find_sub_file(ow.name)
        if f is not None:
            self.unit, self.idx = self.load_file(f), 0
        self.skipping_to_sub = ow.name
        self.skipping_o = ow.name
        self.skip_from = (self.unit_cur, self.cur_idx)

    # o-word keyword -> the method that runs it ("" is a bare o-number)
    _OWORD_HANDLERS: dict[str, Callable[[Flow, OWord], None]] = {
        "": _o_number, "sub": _o_sub, "endsub": _o_return, "return": _o_return, "call": _ocall,
        "do": _o_do, "while": _o_while, "endwhile": _o_endwhile, "repeat": _o_repeat,
        "endrepeat": _o_endrepeat, "break": _o_break, "continue": _o_continue,
        "if": _o_if, "elseif": _o_elseif, "else": _o_else, "endif": _o_endif,
    }


def _round_to_int(v: float) -> int:
    return int(math.floor(v + 0.5))


def _leaves_folder(name: str) -> bool:
    """A subroutine name that, made a file name, would name another folder (``a/b``,
    ``..``, an absolute path): refused, so that lookups stay inside the subroutine path."""
    return "/" in name or "\\" in name or ".." in name or Path(name).is_absolute()
