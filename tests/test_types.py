"""mypy runs clean on the core packages listed under [tool.mypy] in pyproject.toml
(engine, effects, calibration, the modules built on the axis tables, and the G-code
reader: lexer, expansion, interpreter, dialects, path sampling and diff)."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(importlib.util.find_spec("mypy") is None, reason="mypy is not installed")
def test_mypy_is_clean_on_the_core_packages():
    result = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True,
                            check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout
