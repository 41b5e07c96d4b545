"""Dialects are data (STYLE 20): the code asks a Dialect for a fact and
never tests a dialect's name; a new dialect is one entry of postproc.gcode.dialect."""

import ast
import dataclasses
from pathlib import Path

from postproc.gcode import dialect as D

PACKAGE = Path(__file__).parents[1] / "postproc"
# the registry of export formats, some named as the controllers (not dialects)
NOT_DIALECTS = {"metrology/controllers/formats.py"}


def _names_in(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [n for e in node.elts for n in _names_in(e)]
    return []


def test_no_module_but_dialect_py_compares_a_dialect_name():
    names = set(D.DIALECTS)
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel == "gcode/dialect.py" or rel in NOT_DIALECTS:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                hit = [n for side in sides for n in _names_in(side) if n in names]
                if hit:
                    found.append(f"{rel}:{node.lineno}: compares {hit}")
            if isinstance(node, ast.Assign) and isinstance(node.value, (ast.Tuple, ast.Set, ast.List)):
                hit = [n for n in _names_in(node.value) if n in names]
                if len(hit) > 1:  # a list of dialect names kept outside the dialect module
                    found.append(f"{rel}:{node.lineno}: lists {hit}")
    assert not found, "\n".join(found)


def test_a_new_dialect_is_one_entry():
    """Every fact the readers ask has a value on every entry, and an entry made with only
    its limits (every reading fact left at the default) is a working dialect."""
    base = D.DIALECTS["fanuc"]
    new = dataclasses.replace(base, name="example", title="Example 1")
    assert D.get(new) is new
    for d in D.DIALECTS.values():
        assert d.machine in ("mill", "lathe")
        assert d.text_after_percent in ("ignored", "error")
        assert d.off_plane_arc_offset in ("error", "ignored", "ignored-beside-centre", "zero-ignored")
        assert d.macro_syntax in ("o-word", "macro-b", "detect", "sinumerik")
        assert d.reads_arcs_as is None or d.reads_arcs_as in D.DIALECTS


def test_generic_is_the_intersection_of_the_first_five():
    """Entries added later (other controllers) do not narrow what generic writes."""
    g = D.DIALECTS["generic"]
    assert g.max_line_chars == 127
    assert g.max_word_chars == 79
    assert g.comment_forbidden == "(,;"
