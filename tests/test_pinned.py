"""Today's outputs stay as pinned: every golden case and sample, and
the representative subset of the corpus (conftest.corpus_programs; every program with
POSTPROC_FULL_CORPUS=1), corrected with each calibration of benchmarks/pin_outputs.py
(identity, uniform scale, s500 static and parametric; a golden case also with its own
flags), gives the output bytes, refusal and rs274 outcome recorded in
tests/data/pinned/manifest.json.

After a deliberate change, run ``python benchmarks/pin_outputs.py --check`` on the whole
corpus, list every changed program in the closing note, then record again with
``--write tests/data/pinned/``. Identity and scale outputs must never change."""

import sys
from pathlib import Path

import pytest
from conftest import CORPUS, corpus_programs
from oracle import RS274

ROOT = Path(__file__).parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

import pin_outputs  # noqa: E402

PINNED = pin_outputs.DEFAULT_DIR


def _programs():
    chosen = {p.resolve() for p in corpus_programs()}
    items = [(rel, path) for rel, path in pin_outputs.programs()
             if not rel.startswith("corpus/") or path.resolve() in chosen]
    params = [pytest.param(rel, path, id=rel) for rel, path in items]
    if not CORPUS.is_dir():
        params.append(pytest.param("corpus", None, id="corpus",
                                   marks=pytest.mark.skip(reason="no shared corpus at ../shared/corpus")))
    return params


@pytest.fixture(scope="module")
def manifest():
    return pin_outputs.read_manifest(PINNED)


@pytest.mark.parametrize(("rel", "path"), _programs())
def test_outputs_are_as_pinned(rel, path, manifest):
    jobs = pin_outputs.jobs_for([(rel, path)])
    got = {}
    for job in jobs:
        key, rec, _ = pin_outputs.run_case(job, rs274=RS274 is not None)
        got[key] = rec
    old = {key: manifest.get(key) for key, _, _ in jobs}
    changes = pin_outputs.compare(old, got, rs274=RS274 is not None)
    assert not changes, "\n".join(f"{k}\n  old {a}\n  new {b}" for k, a, b in changes)


def test_every_case_is_pinned(manifest):
    """The manifest covers every golden case and sample with every calibration (and the
    whole corpus, where it is present): a new program gets pinned, not skipped."""
    want = {key for key, _, _ in pin_outputs.jobs_for(pin_outputs.programs(corpus=CORPUS.is_dir()))}
    assert want <= set(manifest), sorted(want - set(manifest))[:20]


def test_golden_cases_own_pins_are_their_expected_outputs(manifest):
    """The ``own`` pin of a golden case is the hash of its .out file (the manifest and
    test_correct_cases pin the same bytes)."""
    import hashlib

    for p in sorted((ROOT / "tests" / "cases").glob("*.nc")):
        want = hashlib.sha256(pin_outputs.normalised(p.with_suffix(".out").read_bytes())).hexdigest()
        assert manifest[f"cases/{p.name}|own"]["sha256"] == want, p.name
