"""The measurement frame's registration and what a calibration keeps: a ram sag's offset
taken by the registration must not make the written file worse on the raw points
unannounced. Campaigns from the virtual machine, the sag built by beam theory (postproc.diagnose.vm.ram_sag), never with a candidate's formula."""

from postproc.diagnose import vm
from postproc.diagnose.refit import extend_calibration


def test_ram_sag_taken_by_the_registration_is_warned_with_both_figures():
    """A ram along Y sagging 30 um at full extension under its head, measured in the
    machine's own frame: 'fit --base' with the registration stores the effects without
    the sag's offset and tilt, and is worse than its base on the raw points; the report
    says so, with the figure --no-register gives (no worse than the base)."""
    meas = vm.campaign("random", 1, extra=vm.ram_sag(0.030, 1), frame=False)
    res = vm.check_campaign(meas, offer_empirical=False)
    names = [s["effect"] for s in res.suggestions]
    assert names
    cal = vm.tables_calibration()
    out = extend_calibration(cal, [meas], names, register=True)
    raw = out.info["raw_rms_mm"]
    assert raw["written_mm"] > raw["input_mm"]
    assert raw["without_registration_mm"] <= raw["input_mm"]
    (line,) = [ln for ln in out.report if ln.startswith("warning: on the raw points")]
    assert f"{raw['input_mm'] * 1000:.2f} -> {raw['written_mm'] * 1000:.2f} um" in line
    assert "--no-register" in line
    assert out.info["warnings"]
    kept = extend_calibration(cal, [meas], names, register=False)
    assert kept.info["raw_rms_mm"]["written_mm"] <= raw["input_mm"]
    assert not [ln for ln in kept.report if ln.startswith("warning:")]


def test_a_calibration_better_on_the_raw_points_says_so_without_a_warning():
    mach = vm.machine_with([{"name": "backlash:X", "params": {"b_mm": 0.012}}])
    meas = vm.campaign("random", 22, machine=mach, frame=False)
    out = extend_calibration(vm.tables_calibration(), [meas], ["backlash:X"], register=True)
    raw = out.info["raw_rms_mm"]
    assert raw["written_mm"] < raw["input_mm"]
    assert any(ln.startswith("raw points (no registration)") for ln in out.report)
    assert "warnings" not in out.info
