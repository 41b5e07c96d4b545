"""A calibration whose effect config is wrong is refused on loading, naming the file."""

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.effects import compose, get_effect
from postproc.engine.static import StaticEngine
from postproc.errors import EXIT_CALIBRATION, CalibrationError

REPO = Path(__file__).parents[1]
STATIC = REPO / "calibrations" / "s500_static.json"

BAD = [
    ({"name": "periodic:X", "config": {}, "params": {"cos_mm": 0.002}}, "effect periodic:X has no pitch_mm > 0"),
    ({"name": "thermal:t", "config": {"tau_s": 0}, "params": {"dx_mm": 0.004}}, "effect thermal:t has no tau_s > 0"),
    ({"name": "straightness:Y", "config": {"center_mm": 150, "half_travel_mm": -1}, "params": {}},
     "effect straightness:Y has no half_travel_mm > 0"),
]


def with_effects(tmp_path, effects) -> Path:
    data = json.loads(STATIC.read_text())
    data["effects"] = effects
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data, indent=2))
    return path


@pytest.mark.parametrize(("effect", "message"), BAD, ids=[b[0]["name"] for b in BAD])
def test_a_wrong_effect_config_is_refused_by_load_calibration_with_the_path(tmp_path, effect, message):
    ok = {"name": "backlash:X", "config": {}, "params": {"b_mm": 0.01}}
    path = with_effects(tmp_path, [ok, effect])
    with pytest.raises(CalibrationError) as info:
        load_calibration(path)
    assert info.value.path == str(path)
    assert str(info.value).startswith(f"{path}: {message}")
    assert "postproc fit --effect" in str(info.value)


def test_correct_stops_before_reading_the_program(tmp_path):
    path = with_effects(tmp_path, [BAD[0][0]])
    out = tmp_path / "out.nc"
    result = CliRunner().invoke(main, ["correct", str(REPO / "samples" / "pocket.nc"), "-c", str(path),
                                       "-o", str(out)])
    assert result.exit_code == EXIT_CALIBRATION
    assert f"{path}: effect periodic:X has no pitch_mm > 0 in its config" in result.output
    assert not out.exists()


def test_good_configs_load_and_compose_checks_effect_objects_too(tmp_path):
    good = [get_effect("periodic:Y", config={"pitch_mm": 10.0}, params={"cos_mm": 0.003}).to_dict(),
            get_effect("thermal:t", config={"tau_s": 1800.0}, params={"dx_mm": 0.004}).to_dict(),
            get_effect("straightness:X", config={"center_mm": 150, "half_travel_mm": 150}).to_dict()]
    cal = load_calibration(with_effects(tmp_path, good))
    assert [e.name for e in cal.engine.effects] == ["periodic:Y", "thermal:t", "straightness:X"]
    engine = StaticEngine([[1, 0, 0], [0, 1, 0], [0, 0, 1]], [0, 0, 0], [[0, 0, 0], [315, 315, 315]])
    with pytest.raises(CalibrationError, match="effect periodic:Z has no pitch_mm > 0") as info:
        compose(engine, [get_effect("periodic:Z")])
    assert info.value.path is None  # compose knows no file: load_calibration adds it
