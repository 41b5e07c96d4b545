"""The shop-program corpus (tests/data/shop) stays traceable: every program in it is
listed in SOURCES.csv with its repository, path, commit and licence, and every row of
SOURCES.csv names a program that is there."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import pytest

SHOP = Path(__file__).parent / "data" / "shop"
FOLDERS = {"sinumerik", "g41", "fadal", "okuma"}
#: files of the corpus folder that are not programs
NOT_PROGRAMS = {"SOURCES.csv", "README.md"}
#: licences that allow keeping a copy here (the SPDX-style name opens the cell)
ALLOWED = re.compile(r"^(MIT|BSD-[23]-Clause|Apache-2\.0|ISC|GPL-[23]\.0|LGPL-[23]\.[01]|CC0-1\.0|CC-BY(-SA)?-4\.0)\b")


def _rows() -> list[dict]:
    with open(SHOP / "SOURCES.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _programs() -> set[str]:
    return {p.relative_to(SHOP).as_posix() for p in SHOP.rglob("*")
            if p.is_file() and p.relative_to(SHOP).as_posix() not in NOT_PROGRAMS}


def test_every_program_is_listed_with_a_licence():
    rows = {r["file"]: r for r in _rows()}
    unlisted = sorted(_programs() - set(rows))
    assert not unlisted, f"programs missing from SOURCES.csv: {unlisted}"
    for name in _programs():
        assert ALLOWED.match(rows[name]["licence"]), f"{name}: licence {rows[name]['licence']!r}"


def test_every_row_names_a_program_that_is_there():
    rows = _rows()
    names = [r["file"] for r in rows]
    assert len(names) == len(set(names)), "a file is listed twice"
    missing = sorted(n for n in names if not (SHOP / n).is_file())
    assert not missing, f"SOURCES.csv rows without their file: {missing}"


@pytest.mark.parametrize("row", _rows(), ids=lambda r: r["file"])
def test_row_is_complete(row):
    folder, _, name = row["file"].partition("/")
    assert folder in FOLDERS
    assert name
    assert "/" not in name
    assert row["dialect"] == folder
    assert re.fullmatch(r"[\w.-]+/[\w.-]+", row["repository"])
    assert row["path"]
    assert not row["path"].startswith("/")
    assert re.fullmatch(r"[0-9a-f]{40}", row["commit"])
    assert row["constructs"].strip()
    assert (SHOP / row["file"]).stat().st_size <= 200 * 1024
