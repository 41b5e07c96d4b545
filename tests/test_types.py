"""mypy runs clean on the whole package: ``files = ["postproc"]`` under [tool.mypy] in
pyproject.toml, so a plain ``mypy`` (in CI, through this test, or by hand) checks every
module of postproc with the project's settings."""

import hashlib
import importlib.util
import re
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.skipif(importlib.util.find_spec("mypy") is None, reason="mypy is not installed")
def test_mypy_is_clean_on_the_whole_package():
    # The cache lives outside the checkout (one per checkout): a second run takes seconds.
    cache = Path(tempfile.gettempdir()) / f"postproc-mypy-{hashlib.sha256(str(ROOT).encode()).hexdigest()[:12]}"
    result = subprocess.run([sys.executable, "-m", "mypy", "--cache-dir", str(cache)], cwd=ROOT,
                            capture_output=True, text=True, check=False)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Success" in result.stdout
    # plain mypy (pyproject's files) checked every module of the package
    checked = re.search(r"no issues found in (\d+) source files", result.stdout)
    assert checked is not None, result.stdout
    assert int(checked.group(1)) == len(list((ROOT / "postproc").rglob("*.py")))
