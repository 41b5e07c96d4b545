"""benchmarks/throughput.py times a case to its process's exit: the figures every speed
target is judged by must not wait for the script's memory sampler."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import throughput  # noqa: E402  (a script beside the tests, not a package)


def test_a_case_is_timed_to_its_exit_not_to_the_next_memory_sample(tmp_path):
    # the sampler wakes every 0.5 s after the first second: a child that ends at 1.1 s
    # (and its interpreter's start) was timed at 1.5 s when its exit was noticed only then
    wall, peak_mb, pss_mb = throughput.run_child([sys.executable, "-c", "import time; time.sleep(1.1)"],
                                                 tmp_path / "log")
    assert 1.1 <= wall < 1.48, wall
    assert peak_mb > 0
    assert pss_mb > 0


def test_a_failing_case_stops_the_benchmark(tmp_path):
    with pytest.raises(SystemExit, match="exit code 3"):
        throughput.run_child([sys.executable, "-c", "raise SystemExit(3)"], tmp_path / "log")
