"""ISO 230-2:2014 evaluation: a hand-computed run set, a generated set with known
errors, the runs reader's errors and the iso230 command."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.cli import main
from postproc.errors import MeasurementError
from postproc.metrology.iso230 import evaluate
from postproc.metrology.runs import Runs, format_runs, read_runs

# Three targets (0, 50, 120 mm: uneven), three runs each way, deviations in um.
#   target 0:   up  1, 2, 3   mean  2, s = sqrt((1 + 0 + 1) / 2) = 1
#               down -1,-2,-3 mean -2, s = 1
#   target 50:  up  4, 4, 7   mean  5, s = sqrt((1 + 1 + 4) / 2) = sqrt(3)
#               down 1, 2, 3  mean  2, s = 1
#   target 120: up  0, 2, 4   mean  2, s = sqrt((4 + 0 + 4) / 2) = 2
#               down -6,-4,-2 mean -4, s = 2
HAND = {0.0: ([1, 2, 3], [-1, -2, -3]), 50.0: ([4, 4, 7], [1, 2, 3]), 120.0: ([0, 2, 4], [-6, -4, -2])}
S3 = np.sqrt(3.0)
# Per target (um):
#   B_i = mean_up - mean_down:            4, 3, 6
#   R_up_i = 4 s_up:                       4, 4 sqrt(3), 8
#   R_down_i = 4 s_down:                   4, 4, 8
#   R_i = max(2 s_up + 2 s_down + |B_i|, R_up_i, R_down_i):
#         max(2+2+4, 4, 4) = 8;  max(2 sqrt(3)+2+3, 4 sqrt(3), 4) = 5 + 2 sqrt(3);  max(4+4+6, 8, 8) = 14
#   mean bidirectional (up + down) / 2:   0, 3.5, -1
HAND_TARGETS = {
    "B": [4, 3, 6], "R_up": [4, 4 * S3, 8], "R_down": [4, 4, 8], "R": [8, 5 + 2 * S3, 14],
    "mean": [0, 3.5, -1], "s_up": [1, S3, 2], "s_down": [1, 1, 2],
}
# Per axis (um):
#   B = max |B_i| = 6;  B_mean = (4 + 3 + 6) / 3 = 13/3
#   R_up = 8, R_down = 8, R = 14
#   E_up = 5 - 2 = 3;  E_down = 2 - (-4) = 6;  E = max(all means) - min(all means) = 5 - (-4) = 9
#   M = 3.5 - (-1) = 4.5
#   A_up = max(mean_up + 2 s_up) - min(mean_up - 2 s_up) = (5 + 2 sqrt(3)) - (2 - 4) = 7 + 2 sqrt(3)
#   A_down = max(0, 4, 0) - min(-4, 0, -8) = 12
#   A = max(5 + 2 sqrt(3), 4) - min(-2, -8) = 13 + 2 sqrt(3)
HAND_AXIS = {
    "B": 6, "B_mean": 13 / 3, "R_up": 8, "R_down": 8, "R": 14, "E_up": 3, "E_down": 6, "E": 9,
    "M": 4.5, "A_up": 7 + 2 * S3, "A_down": 12, "A": 13 + 2 * S3,
}


def hand_lines(axis="X", targets=HAND, header="# units: length=mm error=um"):
    """The runs in ISO 230-2's linear cycle: each run up through the targets, then down."""
    lines = ["# postproc iso230 runs v1", header, "axis,target,run,direction,deviation"]
    ps = sorted(targets)
    for j in range(3):
        lines += [f"{axis},{p:.3f},{j + 1},+,{targets[p][0][j]}" for p in ps]
        lines += [f"{axis},{p:.3f},{j + 1},-,{targets[p][1][j]}" for p in reversed(ps)]
    return lines


def write(tmp_path, lines, name="runs.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_hand_computed_figures(tmp_path):
    res = evaluate(read_runs(write(tmp_path, hand_lines())))["X"]
    for key, value in HAND_AXIS.items():
        assert res.figures[key] == pytest.approx(value * 1e-3, abs=1e-12), key
    assert_allclose(res.reversal, np.array(HAND_TARGETS["B"]) * 1e-3, atol=1e-12)
    assert_allclose(res.R_up, np.array(HAND_TARGETS["R_up"]) * 1e-3, atol=1e-12)
    assert_allclose(res.R_down, np.array(HAND_TARGETS["R_down"]) * 1e-3, atol=1e-12)
    assert_allclose(res.R_bi, np.array(HAND_TARGETS["R"]) * 1e-3, atol=1e-12)
    assert_allclose(res.mean, np.array(HAND_TARGETS["mean"]) * 1e-3, atol=1e-12)
    assert_allclose(res.s_up, np.array(HAND_TARGETS["s_up"]) * 1e-3, atol=1e-12)
    assert_allclose(res.s_down, np.array(HAND_TARGETS["s_down"]) * 1e-3, atol=1e-12)
    # 3 runs and 3 targets fall short of the standard; the uneven spacing does not.
    text = "\n".join(res.warnings)
    assert "3 run(s)" in text
    assert "asks for 5" in text
    assert "3 targets over 120 mm" in text
    assert "evenly spaced" not in text
    assert "order" not in text


def test_units_scale_positions_and_errors_separately(tmp_path):
    # length=um with no error unit: both columns are micrometres.
    um = {p * 1000: v for p, v in HAND.items()}
    res = evaluate(read_runs(write(tmp_path, hand_lines(targets=um, header="# units: length=um"))))["X"]
    assert_allclose(res.target_mm, [0, 50, 120])
    assert res.figures["A"] == pytest.approx((13 + 2 * S3) * 1e-3)
    # length=mm error=mm: deviations read as mm.
    res = evaluate(read_runs(write(tmp_path, hand_lines(header="# units: length=mm error=mm"))))["X"]
    assert res.figures["E"] == pytest.approx(9.0)


def test_generated_runs_recover_known_errors():
    """Known systematic error e(P), reversal b(P) and repeatability sigma, many runs."""
    rng = np.random.default_rng(11)
    targets = np.array([0.0, 27.0, 61.5, 88.0, 119.2, 150.0, 176.3, 211.0, 240.7, 270.0, 300.0])
    e = 1.5e-5 * targets + 0.002 * np.sin(targets / 40.0)  # mm
    b = 0.004 + 1e-5 * targets  # mm, B_i
    sigma, n = 0.0005, 400
    axis, tgt, run, direction, dev = [], [], [], [], []
    for j in range(n):
        for d, seq in ((1, range(len(targets))), (-1, reversed(range(len(targets))))):
            for i in seq:
                axis.append("X")
                tgt.append(targets[i])
                run.append(j + 1)
                direction.append(d)
                dev.append(e[i] + d * b[i] / 2 + rng.normal(0.0, sigma))
    k = len(tgt)
    runs = Runs(np.array(axis), np.array(tgt), np.array(run), np.array(direction), np.array(dev),
                np.arange(k, dtype=float), np.arange(k) + 4, "generated")
    res = evaluate(runs)["X"]
    se = sigma / np.sqrt(n)  # standard error of a mean
    assert_allclose(res.mean_up, e + b / 2, atol=5 * se)
    assert_allclose(res.mean_down, e - b / 2, atol=5 * se)
    assert_allclose(res.reversal, b, atol=7 * se)
    assert_allclose(res.s_up, sigma, rtol=0.12)
    assert_allclose(res.s_down, sigma, rtol=0.12)
    # Axis figures from the true values (no noise in the means, s = sigma):
    up, down = e + b / 2, e - b / 2
    assert res.figures["B"] == pytest.approx(b.max(), abs=7 * se)
    assert res.figures["B_mean"] == pytest.approx(b.mean(), abs=3 * se)
    assert res.figures["E"] == pytest.approx(max(up.max(), down.max()) - min(up.min(), down.min()), abs=10 * se)
    assert res.figures["M"] == pytest.approx(np.ptp(e), abs=10 * se)
    true_a = max(up.max(), down.max()) - min(up.min(), down.min()) + 4 * sigma
    assert res.figures["A"] == pytest.approx(true_a, abs=0.0003)
    assert res.figures["R"] == pytest.approx(4 * sigma + b.max(), abs=0.0003)
    assert res.figures["R_up"] == pytest.approx(4 * sigma, rel=0.15)
    assert res.warnings == []


def test_warnings_for_even_spacing_and_order(tmp_path):
    lines = hand_lines(targets={0.0: HAND[0.0], 60.0: HAND[50.0], 120.0: HAND[120.0]})
    # with times t: run 2's up stroke visits 120 before 60
    timed = [lines[0], lines[1], lines[2] + ",t"] + [f"{ln},{k * 10}" for k, ln in enumerate(lines[3:])]
    i = timed.index("X,60.000,2,+,4,70")
    timed[i], timed[i + 1] = "X,60.000,2,+,4,80", "X,120.000,2,+,7,70"
    res = evaluate(read_runs(write(tmp_path, timed)))["X"]
    text = "\n".join(res.warnings)
    assert "evenly spaced (60 mm)" in text
    assert "run 2 (+) does not visit its targets in increasing order by its times t" in text


def test_row_order_is_not_taken_as_visiting_order(tmp_path):
    """Exporters sort rows by target, run or direction: without t no order warning."""
    lines = hand_lines()
    body = sorted(lines[3:], key=lambda ln: (ln.split(",")[3], float(ln.split(",")[1]), ln.split(",")[2]))
    res = evaluate(read_runs(write(tmp_path, lines[:3] + body)))["X"]
    assert not any("order" in w for w in res.warnings)
    rev = lines[:3] + list(reversed(lines[3:]))
    res = evaluate(read_runs(write(tmp_path, rev)))["X"]
    assert not any("order" in w for w in res.warnings)


@pytest.mark.parametrize(("old", "new", "line", "col", "words"), [
    ("X,50.000,1,+,4", "X,50.000,1,up,4", 5, 12, "direction 'up' is not"),
    ("X,50.000,1,+,4", "X,50.000,1.5,+,4", 5, 10, "not a run number"),
    ("X,50.000,1,+,4", "X,50.000,1,+,4um", 5, 14, "not a number"),
    ("X,50.000,1,+,4", "X,0.000,1,+,4", 5, 1, "given twice (first on line 4)"),
])
def test_bad_rows_name_their_place(tmp_path, old, new, line, col, words):
    lines = hand_lines()
    lines[lines.index(old)] = new
    path = write(tmp_path, lines)
    with pytest.raises(MeasurementError) as info:
        read_runs(path)
    assert (info.value.lineno, info.value.col) == (line, col)
    assert words in info.value.message


def test_a_target_without_its_second_direction_is_refused(tmp_path):
    lines = [ln for ln in hand_lines() if not (ln.startswith("X,50.000") and ",-," in ln)]
    with pytest.raises(MeasurementError, match="target 50 mm: 0 run") as info:
        evaluate(read_runs(write(tmp_path, lines)))
    assert info.value.lineno == 5


def test_cli_json_text_and_plot(tmp_path):
    path = write(tmp_path, hand_lines() + [ln.replace("X,", "Y,", 1) for ln in hand_lines()[3:]])
    res = CliRunner().invoke(main, ["iso230", str(path), "--json", "--plot", str(tmp_path / "p.png")])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert sorted(data["axes"]) == ["X", "Y"]
    for key, value in HAND_AXIS.items():
        assert data["axes"]["Y"][key] == pytest.approx(value * 1e-3)
    assert len(data["axes"]["X"]["targets"]) == 3
    assert data["axes"]["X"]["targets"][2]["R"] == pytest.approx(0.014)
    assert "warning: X: 3 run(s)" in res.stderr
    assert (tmp_path / "p.png").stat().st_size > 1000
    res = CliRunner().invoke(main, ["iso230", str(path)])
    assert res.exit_code == 0
    assert "A 16.46 (A+ 10.46, A- 12.00)   E 9.00 (E+ 3.00, E- 6.00)   M 4.50" in res.stdout
    assert "R 14.00 (R+ 8.00, R- 8.00)   B 6.00   mean reversal +4.33" in res.stdout


def test_cli_bad_file_exits_3(tmp_path):
    lines = hand_lines()
    lines[2] = "axis,target,run,dir,deviation"
    res = CliRunner().invoke(main, ["iso230", str(write(tmp_path, lines))])
    assert res.exit_code == 3
    assert "runs.csv:3:1: required column 'direction' is missing" in res.stderr


def test_format_runs_reads_back(tmp_path):
    runs = read_runs(write(tmp_path, hand_lines()))
    path = tmp_path / "again.csv"
    path.write_text(format_runs(runs))
    again = read_runs(path)
    assert_allclose(again.deviation_mm, runs.deviation_mm, atol=1e-9)
    assert_allclose(again.target_mm, runs.target_mm)


# --- completeness of the report (virtual-machine runs) ---------------------

def _vm_runs(tmp_path, name="vm.csv", directions=(1, -1), temps=None, **kw):
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from metrology_machines import TARGETS, x_machine

    from postproc.simulate.runs import simulate_runs

    runs = simulate_runs(x_machine(), "X", TARGETS, rng=np.random.default_rng(4), directions=directions, **kw)
    text = format_runs(runs)
    if temps is not None:
        head, *rows = text.splitlines()[2:]
        extra = ",".join(temps)
        lines = text.splitlines()[:2] + [head + "," + ",".join(n for n in ("temp", "material_temp")[:len(temps)])]
        lines += [r + "," + extra for r in rows]
        text = "\n".join(lines) + "\n"
    path = tmp_path / name
    path.write_text(text)
    return path, runs


def test_expanded_uncertainty_is_stated_with_k2(tmp_path):
    path, _ = _vm_runs(tmp_path)
    res = CliRunner().invoke(main, ["iso230", str(path)])
    assert res.exit_code == 0, res.output
    assert "expanded uncertainty (ISO/TR 230-9, k = 2): U(A)" in res.stdout
    assert "not included: environmental variation error" in res.stdout
    js = json.loads(CliRunner().invoke(main, ["iso230", str(path), "--json"]).stdout)["axes"]["X"]
    u = js["uncertainty_k2"]
    assert u["k"] == 2.0
    # device: 1 um/m (k=2) over 315 mm -> u = 0.1575 um; B compares two means at one target
    assert u["u_device_mm"] == pytest.approx(0.5e-3 * 0.315)
    assert 0 < u["B"] < u["E"]
    # a better laser and a known temperature shrink U(E); B does not depend on them
    path2, _ = _vm_runs(tmp_path, "vm_t.csv", temps=["20.3", "20.1"])
    u2 = json.loads(CliRunner().invoke(main, ["iso230", str(path2), "--json", "--laser-u", "0.2"])
                    .stdout)["axes"]["X"]["uncertainty_k2"]
    assert u2["E"] < u["E"]
    assert u2["B"] == pytest.approx(u["B"])


def test_temperature_is_reported_and_corrected_to_20C(tmp_path):
    plain, _ = _vm_runs(tmp_path)
    out = CliRunner().invoke(main, ["iso230", str(plain)]).stdout
    assert "temperature (ISO 230-2 §4.2): not in the runs file" in out
    warm, _ = _vm_runs(tmp_path, "warm.csv", temps=["21.0", "22.0"])
    out = CliRunner().invoke(main, ["iso230", str(warm)]).stdout
    assert "temp 21.00 °C" in out
    assert "material_temp 22.00 °C" in out
    assert "normal-temperature correction applied" in out
    a = json.loads(CliRunner().invoke(main, ["iso230", str(plain), "--json"]).stdout)["axes"]["X"]
    b = json.loads(CliRunner().invoke(main, ["iso230", str(warm), "--json"]).stdout)["axes"]["X"]
    assert b["temperature_corrected"] is True
    # -alpha (T - 20) P with alpha 11.5 um/(m K), T = 22: -23 um per metre
    for ta, tb in zip(a["targets"], b["targets"], strict=True):
        assert tb["mean_up"] - ta["mean_up"] == pytest.approx(-11.5e-6 * 2.0 * ta["target"], abs=1e-9)
    c = json.loads(CliRunner().invoke(main, ["iso230", str(warm), "--json", "--no-temperature-correction"])
                   .stdout)["axes"]["X"]
    assert c["temperature_corrected"] is False
    assert c["targets"][5]["mean_up"] == pytest.approx(a["targets"][5]["mean_up"])


def test_unidirectional_runs_get_the_one_direction_figures(tmp_path):
    path, runs = _vm_runs(tmp_path, "up.csv", directions=(1,))
    res = evaluate(read_runs(path))["X"]
    assert res.directions == (1,)
    dev = {p: runs.deviation_mm[runs.target_mm == p] for p in np.unique(runs.target_mm)}
    means = np.array([v.mean() for v in dev.values()])
    s = np.array([v.std(ddof=1) for v in dev.values()])
    # (the file holds the deviations to 0.1 nm)
    assert res.figures["E_up"] == pytest.approx(np.ptp(means), abs=2e-7)
    assert res.figures["R_up"] == pytest.approx(4 * s.max(), abs=2e-7)
    assert res.figures["A_up"] == pytest.approx((means + 2 * s).max() - (means - 2 * s).min(), abs=2e-7)
    assert "B" not in res.figures
    assert "M" not in res.figures
    js = json.loads(CliRunner().invoke(main, ["iso230", str(path), "--json", "--plot", str(tmp_path / "u.png")])
                    .stdout)["axes"]["X"]
    assert js["B"] is None
    assert js["E"] is None
    assert js["E_up"] == pytest.approx(np.ptp(means), abs=2e-7)
    assert (tmp_path / "u.png").stat().st_size > 1000
    out = CliRunner().invoke(main, ["iso230", str(path)]).stdout
    assert "unidirectional (+)" in out
    assert "A+ " in out
    # fit takes them: the positioning of that direction, no backlash effect
    res = CliRunner().invoke(main, ["fit", str(path), "-o", str(tmp_path / "u.json")])
    assert res.exit_code == 0, res.output
    assert "approached in + only" in res.stderr


def test_plot_module_imports_matplotlib_lazily():
    import subprocess
    import sys

    code = "import sys, postproc.metrology.iso230, postproc.cli.iso230; print('matplotlib' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
