"""Subprogram calls and returns of the expansion: LinuxCNC M98/M99, Fanuc and Haas
M98/M97/M99 with their L repeats, G65 macro calls with Argument specification I, and
the call frames they open and close."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from postproc.gcode.expand_state import (
    FANUC_ARGUMENTS_I,
    FANUC_LOCALS,
    MAX_CALL_DEPTH,
    CallFrame,
    ExpanderState,
)
from postproc.gcode.expand_syntax import (
    Unit,
    Word,
)
from postproc.gcode.expr import (
    NULL,
)


class Calls(ExpanderState):
    # -- subprogram calls (M98 / M99 / G65) ----------------------------------
    def _call_words(self, words: list[tuple[Word, Any]], m_codes: list[float],
                    g_codes: list[float]) -> tuple[Callable[[], None] | None, set[int]]:
        """The call a block makes and the indices of the words it uses (``words``: each
        word with its value, a number or NULL)."""
        letters: dict[str, list[tuple[int, Word, Any]]] = {}
        for k, (w, v) in enumerate(words):
            letters.setdefault(w.letter, []).append((k, w, v))
        if 99.0 in m_codes:
            if len(self.frames) == 1 and "P" not in letters:
                # M99 ending the main program: the end of one pass (a subprogram file
                # corrected on its own, or a program the controller repeats: each pass is
                # corrected alike; the interpreter refuses it in G91, where each pass would
                # start elsewhere). The line stays as it is and expansion stops there.
                return None, set()
            return self._m99_words(letters)
        if 97.0 in m_codes and self.fanuc:
            return self._m97_words(letters)
        if 98.0 in m_codes:
            return self._m98_words(letters)
        return self._g65_words(words, letters)

    def _m99_words(self, letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """M99 [P..]: return from the subprogram (to sequence number P)."""
        drop = {k for k, _w, v in letters.get("M", []) if v == 99.0}
        target: tuple[int, int] | None = None
        for k, w, v in letters.get("P", []):
            drop.add(k)
            if v is not NULL:  # a vacant variable's address is ignored (P#0: none)
                target = (int(round(v)), w.col)
        return (lambda: self._m99(target)), drop

    def _m97_words(self, letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """M97 P.. [L..] (Haas): call the local subprogram at sequence number P, L times."""
        p, drop = self._p_l_words(letters, 97.0, "M97 needs P (the sequence number of the local subprogram)")
        number = int(round(p[2]))
        given = _count(letters)
        count = 1 if given is None else given
        return (lambda: self._m97(number, count, p[1].col)), drop

    def _m98_words(self, letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """M98 P.. [L..]: call subprogram O(P), L times."""
        p, drop = self._p_l_words(letters, 98.0, "M98 needs P (the subprogram number)")
        number = int(round(p[2]))
        repeats = _count(letters)
        return (lambda: self._m98(number, repeats, p[1].col)), drop

    def _p_l_words(self, letters: dict[str, list[tuple[int, Word, Any]]], code: float,
                   missing_p: str) -> tuple[tuple[int, Word, Any], set[int]]:
        """The first P of an M97/M98 call (``code``) and the indices of its M, P and L words;
        ``missing_p`` is the error when there is no P."""
        mw = next(w for k, w, v in letters["M"] if v == code)
        drop = {k for k, _w, v in letters.get("M", []) if v == code}
        drop.update(k for k, _, _ in letters.get("P", []) + letters.get("L", []))
        # a vacant variable's address is ignored (P#0: as if no P)
        p = [x for x in letters.get("P", []) if x[2] is not NULL]
        if not p:
            raise self.error(mw.col, missing_p)
        return p[0], drop

    def _g65_words(self, words: list[tuple[Word, Any]],
                   letters: dict[str, list[tuple[int, Word, Any]]]) -> tuple[Callable[[], None], set[int]]:
        """G65 P.. [L..] arguments: call macro O(P), L times, with the arguments as its locals
        (argument specification I). Every word of the block belongs to the call."""
        gw = next(w for k, w, v in letters["G"] if v == 65.0)
        if not self.fanuc:
            raise self.refuse(gw.col, "G65 macro call is Fanuc/Haas syntax",
                              hint="choose --dialect fanuc or haas for this program")
        args: dict[str, Any] = {}
        macro: int | None = None
        count = 1
        for w, v in words:
            if w.letter == "G":
                if v != 65.0:
                    raise self.refuse(w.col, "G65 must be alone in its block with its arguments")
            elif w.letter == "P":
                if v is not NULL:  # a vacant variable's address is ignored
                    macro = int(round(v))
            elif w.letter == "L":
                if v is not NULL:
                    count = int(round(v))
            elif w.letter != "N":
                self._g65_argument(args, w, v)
        if macro is None:
            raise self.error(gw.col, "G65 needs P (the macro program number)")
        return (lambda: self._g65(macro, count, args, gw.col)), set(range(len(words)))

    def _g65_argument(self, args: dict[str, Any], w: Word, v: Any) -> None:
        """Add word ``w`` (value ``v``) to the arguments ``args`` of a G65 call."""
        if w.letter not in FANUC_ARGUMENTS_I:
            raise self.error(w.col, f"address {w.letter} cannot be a G65 argument")
        if w.node is None and "." not in w.raw and v != 0.0:
            raise self.refuse(w.col, f"G65 argument {w.letter}{w.raw} has no decimal point: the "
                              "control scales it by its least input increment, which is "
                              "machine configuration", hint=f"write {w.letter}{w.raw}. (with a point)")
        if w.letter in args:
            raise self.refuse(w.col, f"argument {w.letter} given twice (argument specification II "
                              "is not supported)")
        args[w.letter] = v

    def _program_target(self, number: int, col: int) -> tuple[Unit, int, int] | None:
        progs = self.main.programs()
        if number in progs:
            return self.main, progs[number], number
        if self.unit_cur is not self.main and number in self.unit_cur.programs():
            return self.unit_cur, self.unit_cur.programs()[number], number
        f = self.find_program_file(number)
        if f is not None:
            u = self.load_file(f)
            start = u.programs().get(number)
            return u, (start if start is not None else -1), number
        return None

    def _m98(self, number: int, count: int | None, col: int) -> None:
        target = self._program_target(number, col)
        repeat = 1 if count is None else count
        if target is None and count is None and number >= 10000 and (
                self.fanuc or self.d.m98_count_in_p):
            # Fanuc: P(count)(4-digit program number)
            target = self._program_target(number % 10000, col)
            repeat = number // 10000
            number = number % 10000
        if target is None:
            raise self.error(col, f"subprogram O{number} not found in the file or on the subroutine path",
                             hint=f"add 'O{number}' ... M99 after the main program's M30, or put O{number}.nc "
                             "on --subroutine-path")
        if repeat <= 0:
            return
        self.will_repeat(repeat, col)
        unit, start, _ = target
        self._enter("m98", f"O{number}", unit, start + 1, repeat - 1)

    def _m97(self, number: int, count: int, col: int) -> None:
        if count <= 0:
            return
        self.will_repeat(count, col)
        start = self._sequence(self.main, number, 0, col)
        self._enter("m98", f"N{number}", self.main, start, count - 1)

    def _g65(self, number: int, count: int, args: dict, col: int) -> None:
        target = self._program_target(number, col)
        if target is None:
            raise self.error(col, f"macro program O{number} not found in the file or on the subroutine path")
        if count <= 0:
            return
        self.will_repeat(count, col)
        unit, start, _ = target
        local = [NULL] * (FANUC_LOCALS + 1)
        for letter, v in args.items():
            local[FANUC_ARGUMENTS_I[letter]] = v
        self._enter("g65", f"O{number}", unit, start + 1, count - 1, saved=local)

    def _enter(self, call_type: str, name: str, unit: Unit, start: int, repeats: int,
               saved: list | None = None) -> None:
        if len(self.frames) > MAX_CALL_DEPTH:
            raise self.refuse(1, f"subprogram calls nested deeper than {MAX_CALL_DEPTH} levels",
                              hint="check for a subprogram that calls itself")
        self.count_iteration(1)
        fr = CallFrame(call_type=call_type, ret_unit=self.unit_cur, ret_idx=self.cur_idx + 1,
                    saved=saved, repeats_left=repeats, start_unit=unit, start_idx=start, sub_name=name,
                    call_lineno=self.cur_idx + 1, call_path=self.unit_cur.path)
        self.frames.append(fr)
        self.version += 1
        self.unit, self.idx = unit, start

    def _m99(self, target: tuple[int, int] | None) -> None:
        if len(self.frames) == 1:
            raise self.refuse(1, "M99 P.. in the main program jumps back into it forever",
                              hint="end the main program with M30")
        fr = self.frames[-1]
        if fr.call_type not in ("m98", "g65"):
            raise self.error(1, "M99 inside an o-word subroutine", hint="end it with 'o<name> endsub'")
        if fr.repeats_left > 0:
            self.count_iteration(1)
            fr.repeats_left -= 1
            self.version += 1
            if fr.call_type == "g65":
                pass  # locals persist across G65 L repeats
            if fr.start_unit is None:  # pragma: no cover - _enter sets it
                raise AssertionError(f"{fr.call_type} frame without the start of its repeats")
            self.unit, self.idx = fr.start_unit, fr.start_idx
            return
        self._leave(fr)
        if target is not None:
            number, col = target
            self.idx = self._sequence(self.unit, number, fr.ret_idx, col)
            if self.idx < fr.ret_idx:  # back to or before the call: one more pass of a loop
                self.count_iteration(col)
                self._another_pass(col)

    def _leave(self, fr: CallFrame) -> None:
        """Return from ``fr``, the innermost subprogram frame, to the line after its call."""
        self.frames.pop()
        self.version += 1
        if fr.ret_unit is None:  # pragma: no cover - callers never leave the main program's frame
            raise AssertionError("the main program's frame has no caller to return to")
        self.unit, self.idx = fr.ret_unit, fr.ret_idx

    def _sequence(self, unit: Unit, number: int, start: int, col: int) -> int:
        """Fanuc sequence-number search: forward from ``start``, then from the program start."""
        hits = unit.sequence_numbers().get(number, [])
        lo = self._program_start(unit, start)
        for k in hits:
            if k >= start and self._program_start(unit, k) == lo:
                return k
        for k in hits:
            if lo <= k < start:
                return k
        raise self.error(col, f"sequence number N{number} not found in this program",
                         hint="GOTO/M99 P jump to a block that starts with that N number")

    def _program_start(self, unit: Unit, idx: int) -> int:
        starts = sorted(unit.programs().values())
        lo = 0
        for s in starts:
            if s <= idx:
                lo = s
        return lo


def _count(letters: dict[str, list[tuple[int, Word, Any]]]) -> int | None:
    """The repeat count of a call's first L word, or None without one (an L of a vacant
    variable is ignored, as the control ignores any such address)."""
    ls = [v for _k, _w, v in letters.get("L", []) if v is not NULL]
    return int(round(ls[0])) if ls else None
