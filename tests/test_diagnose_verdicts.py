"""Verdicts judged on held-out data, random and spatial splits, each naming its cause with
its evidence in one line. Campaigns from the virtual machine
(postproc.diagnose.vm); errors outside the catalogue are written here, never with a
candidate effect's own formula."""

import numpy as np

from postproc.diagnose import vm
from postproc.diagnose.refit import fit_with_effects
from postproc.diagnose.text import format_report
from postproc.diagnose.verdict import CONSISTENT_RATIO

VERDICTS = {"consistent", "missing-effect", "model-too-stiff", "campaign-limited", "unexplained"}


def verdict_line(res) -> str:
    (line,) = [ln for ln in format_report(res) if ln.startswith("verdict: ")]
    assert "\n" not in line
    return line


def test_clean_campaign_is_consistent_with_its_evidence():
    res = vm.check_campaign(vm.campaign("planes", 21), offer_empirical=False)
    assert res.verdict == "consistent"
    v = res.verdict_info
    assert v.random_ratio <= CONSISTENT_RATIO
    assert v.spatial_ratio <= CONSISTENT_RATIO
    line = verdict_line(res)
    assert "random folds" in line
    assert "slabs" in line
    assert res.to_json()["verdict_evidence"] == v.evidence


def test_missing_effect_names_it_and_holds_on_held_out_slabs():
    mach = vm.machine_with([{"name": "backlash:X", "params": {"b_mm": 0.012}}])
    res = vm.check_campaign(vm.campaign("random", 22, machine=mach), offer_empirical=False)
    assert res.verdict == "missing-effect"
    assert res.verdict_info.details["effects"] == ["backlash:X"]
    assert verdict_line(res).startswith("verdict: missing-effect: backlash:X: held-out RMS with them")


def test_local_bump_fitted_as_a_global_shape_fails():
    """A 15 um bump on a fifth of the X travel: random folds accept a whole-travel shape,
    slabs held out do not."""
    def bump(q, r, ctx):
        out = np.zeros_like(q)
        out[:, 0] = 0.015 * np.exp(-0.5 * ((q[:, 0] - 240.0) / 20.0) ** 2)
        return out
    res = vm.check_campaign(vm.campaign("random", 319, n=90, extra=bump), offer_empirical=False)
    assert res.verdict == "unexplained", verdict_line(res)
    v = res.verdict_info
    assert v.spatial_ratio > CONSISTENT_RATIO
    assert v.spatial_ratio > v.random_ratio
    assert "held out" in v.evidence


def test_a_widened_tolerance_does_not_pass_a_local_bump():
    """Heavy-tailed noise widens 1.15 (the floor is less certain); a held-out split 1.1 x
    worse than the random folds is not the floor, and the bump fitted as a whole-travel
    shape stays unexplained (this campaign: 1.04 random, 1.18 on the X slabs)."""
    def bump(q, r, ctx):
        out = np.zeros_like(q)
        out[:, 0] = 0.015 * np.exp(-0.5 * ((q[:, 0] - 240.0) / 20.0) ** 2)
        return out
    res = vm.check_campaign(vm.campaign("random", 327, n=90, extra=bump), offer_empirical=False)
    assert res.noise.heavy_tailed
    assert res.verdict == "unexplained", verdict_line(res)
    assert res.verdict_info.spatial_ratio > CONSISTENT_RATIO


def test_per_visit_scatter_is_campaign_limited():
    res = vm.check_campaign(vm.campaign("random", 23, visit_sigma_mm=0.004), offer_empirical=False)
    assert res.verdict == "campaign-limited", verdict_line(res)
    assert "spatially white" in res.verdict_info.evidence
    assert res.verdict_info.details["cause"] == "repeatability"


def test_tilt_is_named_on_heavy_tailed_noise_and_clean_campaigns_stay_consistent():
    """Student-t tracker noise (4 degrees of freedom), 120 pairs: on this seed the noise
    itself sits 8 % above the floor its repeats give, and a true 60 urad tilt, named, was
    judged 'unexplained' (1.09 random folds, 1.17 on the Y slabs). The verdict now allows for
    the floor's uncertainty under heavy tails; clean campaigns of the same noise stay
    consistent (benchmarks/diagnose_matrix.py --clean counts them on 40 more)."""
    tilt = vm.machine_with([{"name": "abbe:tilt", "params": {"wx_rad": 6e-5, "wy_rad": 0.0, "wz_rad": 0.0}}])
    res = vm.check_campaign(vm.campaign("tools", 319, machine=tilt), offer_empirical=False)
    assert res.noise.heavy_tailed
    assert res.verdict == "missing-effect", verdict_line(res)
    assert res.verdict_info.details["effects"] == ["abbe:tilt"]
    assert "widened for heavy-tailed noise" in res.verdict_info.evidence
    for seed in (319, 320, 321, 322):
        clean = vm.check_campaign(vm.campaign("tools", seed), max_selected=1, offer_empirical=False)
        assert clean.verdict == "consistent", (seed, verdict_line(clean))


def _load_steps(t, rng):
    return np.repeat([0.0, 250.0, 500.0], -(-len(t) // 3))[:len(t)][rng.permutation(len(t))]


def test_load_times_position_is_named_and_holds_on_the_load_step_held_out():
    """A ram along Y sagging under the load it carries (beam theory: the sag grows with the
    load and the cube of the free length, the end turns and acts through the tool), 20 um
    at the full load and extension. Load plus a fixed shape passed it (1.09 x on the load
    steps); the load x position term names it, and holds on each load step left out."""
    sag = vm.ram_sag(0.020, 1, load_column="load", load_max=500.0)
    res = vm.check_campaign(vm.campaign("logged", 331, context={"load": _load_steps}, extra=sag),
                            offer_empirical=False)
    assert res.verdict == "missing-effect", verdict_line(res)
    assert "loadpos:Y" in res.verdict_info.details["effects"]
    assert "load levels" in res.verdict_info.evidence
    assert res.verdict_info.spatial_ratio <= CONSISTENT_RATIO
    assert res.ranking.base_cv_rms_mm / res.noise.rms_mm > CONSISTENT_RATIO


def test_a_load_step_left_out_fails_load_plus_a_fixed_shape():
    """Without the load x position term (a catalogue that lacks it), a 50 um sag is fitted as
    load plus a fixed shape, which misses the load step it did not see."""
    from postproc.effects import candidate_names

    sag = vm.ram_sag(0.050, 1, load_column="load", load_max=500.0)
    meas = vm.campaign("logged", 24, context={"load": _load_steps}, extra=sag)
    names = [n for n in candidate_names(["t", "temp", "load"]) if not n.startswith("loadpos:")]
    res = vm.check_campaign(meas, candidates=names, offer_empirical=False)
    assert res.verdict not in ("consistent", "missing-effect"), verdict_line(res)
    assert "load levels" in res.verdict_info.evidence


def test_stiff_static_model_is_model_too_stiff():
    """A static calibration of the S500-like machine (bows of 0.1 mm): a finer model of the
    same family, the static terms as functions of position, explains the points."""
    from postproc.calfile import calibration_from_dict, calibration_to_dict

    meas = vm.campaign("random", 25, n=120)
    fitted = fit_with_effects("static", [meas], [])
    cal = calibration_from_dict(calibration_to_dict(fitted.engine, name="st", fit=fitted.info), path="st.json")
    res = vm.check_campaign(meas, cal, fixed=False, max_selected=1, offer_empirical=False)
    assert res.verdict == "model-too-stiff", verdict_line(res)
    assert "parametric" in res.verdict_info.details["finer_model"]


def test_tracker_moved_during_the_campaign_is_a_frame_jump_named_with_its_row():
    """The tracker knocked after 60 % of the rows (10 um and 20 urad, rigid): it was
    'unexplained' with thermal:t suggested; now campaign-limited, the jump found at its row."""
    res = vm.check_campaign(vm.campaign("random", 1, moved=(0.6, 0.010, 2e-5)), offer_empirical=False)
    assert res.verdict == "campaign-limited", verdict_line(res)
    assert res.verdict_info.details["cause"] == "frame jump"
    assert abs(res.verdict_info.details["row"] - 145) <= 2
    assert "register the two parts separately" in verdict_line(res)
    assert res.to_json()["frame_jump"]["size_mm"] > 0.008


def test_clean_campaigns_and_a_warm_up_give_no_frame_jump():
    from postproc.diagnose.check import measured_residual
    from postproc.diagnose.data import Dataset
    from postproc.diagnose.jump import frame_jump

    engine = vm.tables_calibration().engine
    warm = vm.machine_with([{"name": "thermal:t", "config": {"tau_s": 2400.0},
                             "params": {"dx_mm": 0.0, "dy_mm": 0.004, "dz_mm": 0.015}}])
    measured = [vm.campaign(shape, 900 + i) for i, shape in enumerate(vm.SHAPES)]
    measured += [vm.campaign("random", 340 + i, machine=warm) for i in range(2)]
    for meas in measured:
        ds = Dataset.from_measurements([meas])
        jump = frame_jump(ds, measured_residual(engine, ds))
        assert jump is None, (meas.path, jump.describe())
    moved = Dataset.from_measurements([vm.campaign("planes", 5, moved=(0.5, 0.010, 2e-5))])
    jump = frame_jump(moved, measured_residual(engine, moved))
    assert jump is not None
    assert abs(jump.row - 150) <= 3
