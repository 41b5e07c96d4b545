"""The shape of the G-code lane: in postproc/gcode/ no class over 400
lines, no function over 80 lines and none with more than 8 parameters (``self`` and
``cls`` not counted). What does not meet it yet is listed in KNOWN with its size today:
a listed size may only shrink, nothing new may join the list, and an entry that meets
the rule must leave it. Run ``python tests/test_shape.py`` to print today's offenders."""

from __future__ import annotations

import ast
from pathlib import Path

GCODE = Path(__file__).resolve().parents[1] / "postproc" / "gcode"
MAX_CLASS_LINES = 400
MAX_FUNCTION_LINES = 80
MAX_PARAMETERS = 8

#: (file, qualified name, what) -> the size today. ``what``: "lines" or "parameters".
KNOWN: dict[tuple[str, str, str], int] = {}


def _parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    a = fn.args
    names = [x.arg for x in (*a.posonlyargs, *a.args, *a.kwonlyargs)]
    if names and names[0] in ("self", "cls"):
        names = names[1:]
    return len(names)


def offenders(root: Path = GCODE) -> dict[tuple[str, str, str], int]:
    """Every class, function and method of ``root``'s modules that breaks a limit: its
    (file, qualified name, what) and its size."""
    found: dict[tuple[str, str, str], int] = {}

    def visit(node: ast.AST, prefix: str, file: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                name = prefix + child.name
                size = child.end_lineno - child.lineno + 1
                if size > MAX_CLASS_LINES:
                    found[(file, name, "lines")] = size
                visit(child, name + ".", file)
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                size = child.end_lineno - child.lineno + 1
                if size > MAX_FUNCTION_LINES:
                    found[(file, name, "lines")] = size
                if _parameters(child) > MAX_PARAMETERS:
                    found[(file, name, "parameters")] = _parameters(child)
                visit(child, name + ".", file)

    for path in sorted(root.glob("*.py")):
        visit(ast.parse(path.read_text(encoding="utf-8")), "", path.name)
    return found


def test_no_new_or_grown_offender():
    now = offenders()
    new = {k: v for k, v in now.items() if k not in KNOWN}
    grown = {k: (KNOWN[k], v) for k, v in now.items() if k in KNOWN and v > KNOWN[k]}
    assert not new, f"over the limits (class {MAX_CLASS_LINES} lines, function {MAX_FUNCTION_LINES} lines, " \
                    f"{MAX_PARAMETERS} parameters): {new}"
    assert not grown, f"grown since listed (listed, now): {grown}"


def test_the_list_only_names_what_still_breaks_a_limit():
    now = offenders()
    gone = sorted(k for k in KNOWN if k not in now)
    assert not gone, f"these meet the limits now: take them off KNOWN: {gone}"
    shrunk = {k: (v, now[k]) for k, v in KNOWN.items() if k in now and now[k] < v}
    assert not shrunk, f"these shrank: list their size today (listed, now): {shrunk}"


def test_the_check_sees_what_it_must(tmp_path):
    """The check is not blind: a class, a function and a parameter list over the limits
    are all found, nested ones too."""
    body = "\n".join(f"    x{i} = {i}" for i in range(MAX_FUNCTION_LINES))
    (tmp_path / "m.py").write_text(
        f"def long():\n{body}\n\n"
        f"def wide({', '.join(f'a{i}' for i in range(MAX_PARAMETERS + 1))}):\n    pass\n\n"
        "class Big:\n" + "\n".join(f"    y{i} = {i}" for i in range(MAX_CLASS_LINES)) + "\n"
        "    def m(self, " + ", ".join(f"b{i}" for i in range(MAX_PARAMETERS)) + "):\n        pass\n"
        "    def n(self, " + ", ".join(f"b{i}" for i in range(MAX_PARAMETERS + 1)) + "):\n        pass\n")
    got = offenders(tmp_path)
    assert set(got) == {("m.py", "long", "lines"), ("m.py", "wide", "parameters"), ("m.py", "Big", "lines"),
                        ("m.py", "Big.n", "parameters")}


if __name__ == "__main__":
    import sys

    sys.stdout.writelines(f"    {key!r}: {size},\n" for key, size in sorted(offenders().items()))
