import zlib

import numpy as np
import pytest

from postproc.diagnose.crossval import make_folds
from postproc.diagnose.data import Dataset
from postproc.diagnose.models import Fixed, LinearStatic
from postproc.diagnose.noise import noise_floor
from postproc.diagnose.rank import rank_effects
from postproc.diagnose.synthetic import (
    NEEDS_IDENTITY_BASE,
    SIGMA_MM,
    SPECS,
    identity_machine,
    make_data,
)
from postproc.effects import candidate_names

# Visible size of each hidden effect (RMS of the part the base model cannot absorb),
# in units of the per-axis noise sigma: inside the 2-4 x noise range.
SIZE_SIGMAS = 2.5
FOLDS = 4
# "within 15 % of the noise floor"
FLOOR_MARGIN = 1.15


def rank(meas, base):
    ds = Dataset.from_measurements([meas])
    model = LinearStatic() if base == "static" else Fixed(identity_machine(), "test")
    folds = make_folds(ds.repeat_groups(), FOLDS)
    return ds, rank_effects(model, ds, [], candidate_names(ds.ctx), folds, max_selected=2)


@pytest.mark.parametrize("name", sorted(SPECS))
def test_one_hidden_effect_is_ranked_first_and_removes_the_misfit(name):
    base = "identity" if name in NEEDS_IDENTITY_BASE else "static"
    meas, (truth,) = make_data([(SPECS[name], SIZE_SIGMAS)], base=base, seed=zlib.crc32(name.encode()) % 1000)
    ds, rk = rank(meas, base)
    floor = noise_floor(ds)
    assert floor.source == "repeats"
    assert floor.rms_mm == pytest.approx(SIGMA_MM * np.sqrt(3), rel=0.15)
    assert rk.rounds[0][0].name == name
    assert [c.name for c in rk.selected] == [name]
    assert rk.base_cv_rms_mm > 1.3 * floor.rms_mm  # the misfit was real
    assert rk.final_cv_rms_mm < FLOOR_MARGIN * floor.rms_mm
    fitted = next(e for e in rk.final_effects if e.name == name)
    # the fitted size is that of the hidden effect (within the noise)
    d_true = truth.displacement(ds.q, ds.r, ds.ctx)
    d_fit = fitted.displacement(ds.q, ds.r, ds.ctx)
    err = np.sqrt(np.mean(np.sum((d_fit - d_true - (d_fit - d_true).mean(axis=0)) ** 2, axis=1)))
    assert err < 0.5 * SIZE_SIGMAS * SIGMA_MM


@pytest.mark.parametrize("seed", [3, 4])
def test_no_hidden_effect_no_suggestion(seed):
    meas, _ = make_data([], seed=seed)
    ds, rk = rank(meas, "static")
    assert rk.selected == []
    assert rk.final_cv_rms_mm < FLOOR_MARGIN * noise_floor(ds).rms_mm
    assert all(c.status == "not significant" for c in rk.rounds[0])


@pytest.mark.parametrize(("big", "small"), [("backlash:X", "periodic:Y"), ("thermal:t", "abbe:tilt")])
def test_two_hidden_effects_found_in_order_of_size(big, small):
    specs = [(SPECS[small], 2.5), (SPECS[big], 4.0)]
    meas, _ = make_data(specs, seed=40, n_points=80)
    ds, rk = rank(meas, "static")
    assert [c.name for c in rk.selected] == [big, small]
    assert rk.selected[0].explained > rk.selected[1].explained > 0
    assert rk.final_cv_rms_mm < FLOOR_MARGIN * noise_floor(ds).rms_mm


def test_untestable_effects_are_reported_with_the_reason():
    meas, _ = make_data([], seed=8, n_points=40)
    meas.context.pop("load")
    meas.r[:] = [0, 0, -100.0]
    meas.direction[:, 1] = 1.0
    ds, rk = rank(meas, "static")
    why = {c.name: c.reason for c in rk.untestable}
    assert "no load column" in why["load:load"]
    assert "tool vectors vary" in why["abbe:tilt"]
    assert "diry does not vary" in why["backlash:Y"]
    assert {"scale:X", "squareness:XY"} <= {c.name for c in rk.in_model}
