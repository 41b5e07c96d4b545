"""The pockets command end to end: plan -> corrected program -> machined pocket -> plan.

Each program the command writes is read back with the program path reader, run
through the shell machine's geometry (the static calibration's forward model, so the
geometric correction cancels exactly when it is right) and the thickness left at
the gauge nodes is what the synthetic shell gives for the correction the program
really carries. The loop is the one of test_mirror_selftune, but through G-code.
"""

import re

import numpy as np
from click.testing import CliRunner

from postproc.calfile import load_calibration
from postproc.cli import main
from postproc.gcode.path import program_path
from postproc.mirror.synthetic import (
    Shell,
    plan_csv,
    pocket_program,
    sensor_csv,
    shell_calibration_text,
    thickness_csv,
)

BAND_HALF_MM = 0.020
Y_BOTTOM = -5.0


def carried_correction(program, shell, engine):
    """Cut-deeper amount at each gauge node of the program (actual Y minus nominal Y)."""
    pp = program_path(program)
    feed = ~pp.rapid
    pts, b_prog = pp.points_mm[feed], pp.context["B"][feed]
    actual = engine.forward(pts - pp.tool_mm[feed], pp.tool_mm[feed])
    b, z = shell.local_grid()
    out = np.empty(len(b))
    for k, (bb, zz) in enumerate(zip(b, z, strict=True)):
        hit = np.flatnonzero((np.abs(b_prog - bb) < 1e-6) & (np.abs(pts[:, 2] - zz) < 1e-6))
        assert len(hit), (bb, zz)
        out[k] = actual[hit[-1], 1] - Y_BOTTOM
    return out


def test_pockets_command_closes_the_loop(tmp_path):
    shell = Shell()
    (tmp_path / "sensor.csv").write_text(sensor_csv(shell.sensor_sweep()))
    (tmp_path / "pocket.nc").write_text(pocket_program(shell, Y_BOTTOM))
    (tmp_path / "cal.json").write_text(shell_calibration_text())
    engine = load_calibration(tmp_path / "cal.json").engine
    runner = CliRunner()
    res = runner.invoke(main, ["mirror", "kdist", str(tmp_path / "sensor.csv"), "--cutter-radius", "10",
                               "--diameter", "2000", "--segment-deg", "2", "-o", str(tmp_path / "kdist.csv")])
    assert res.exit_code == 0, res.output
    b, z = shell.local_grid()
    rows = [("", "")] * shell.n_pockets
    semi_pockets, finish_err = [], {}
    for _ in range(3 * shell.n_pockets):
        (tmp_path / "plan.csv").write_text(plan_csv(shell, rows))
        res = runner.invoke(main, [
            "mirror", "pockets", str(tmp_path), "-c", str(tmp_path / "cal.json"),
            "--program", str(tmp_path / "pocket.nc"), "--t-ref", "2.0", "--band", "1.98,2.02",
            "--allowance", "0.3", "--kdist", str(tmp_path / "kdist.csv"), "-o", str(tmp_path / "out")])
        assert res.exit_code == 0, res.output
        if "all pockets of the plan are finished" in res.output:
            break
        name, kind = re.search(r"wrote \S+/(P\d\d)_(semi|finish)\.nc", res.output).groups()
        i = int(name[1:]) - 1
        k = carried_correction(tmp_path / "out" / f"{name}_{kind}.nc", shell, engine)
        thk = shell.machine(i, b, z, k)
        (tmp_path / f"{name}_{kind}.csv").write_text(thickness_csv(thk, kind))
        if kind == "semi":
            semi_pockets.append(i)
            rows[i] = (f"{name}_{kind}.csv", rows[i][1])
            # the semi-finish program leaves the allowance b and removes E_dist: what is left
            # is T_ref + b + the within-pocket pattern + the drift (gauge noise, K_dist estimate)
            left = thk.t_mm - (2.3 + shell.pattern(b, z) + shell.drift_mm * i)
            assert np.abs(left).max() < 0.004
        else:
            rows[i] = (rows[i][0], f"{name}_{kind}.csv")
            finish_err[i] = thk.t_mm - shell.t_ref_mm
            assert (tmp_path / "out" / f"{name}_kfb.csv").is_file()
    assert semi_pockets == shell.expected_relearns(BAND_HALF_MM, with_kdist=True)
    assert sorted(finish_err) == list(range(shell.n_pockets))
    worst = max(np.abs(e).max() for e in finish_err.values())
    assert worst < BAND_HALF_MM + shell.drift_mm + 0.004
    assert "OUT OF BAND" in res.output


def test_out_of_map_names_the_template_line(tmp_path):
    shell = Shell()
    prog = pocket_program(shell, Y_BOTTOM).replace("B3.7500", "B9.0000", 1)
    lineno = next(k for k, ln in enumerate(prog.splitlines(), 1) if "B9.0000" in ln)
    (tmp_path / "pocket.nc").write_text(prog)
    (tmp_path / "cal.json").write_text(shell_calibration_text())
    b, z = shell.local_grid()
    (tmp_path / "s.csv").write_text(thickness_csv(shell.machine(0, b, z, -0.3), "semi"))
    (tmp_path / "plan.csv").write_text(plan_csv(shell, [("s.csv", "")]))
    res = CliRunner().invoke(main, [
        "mirror", "pockets", str(tmp_path / "plan.csv"), "-c", str(tmp_path / "cal.json"),
        "--program", str(tmp_path / "pocket.nc"), "--t-ref", "2.0", "--band", "1.98,2.02",
        "--allowance", "0.3", "-o", str(tmp_path / "out")])
    assert res.exit_code == 5, res.output
    assert f"pocket.nc:{lineno}:" in res.output
    assert "outside the correction map" in res.output
    assert not (tmp_path / "out" / "P01_finish.nc").exists()
    res = CliRunner().invoke(main, [
        "mirror", "pockets", str(tmp_path / "plan.csv"), "-c", str(tmp_path / "cal.json"),
        "--program", str(tmp_path / "pocket.nc"), "--t-ref", "2.0", "--band", "1.98,2.02",
        "--allowance", "0.3", "--clamp", "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "out" / "P01_finish.nc").is_file()


def _finish_job(tmp_path, template_text: str) -> list[str]:
    """The files of a plan whose next job is pocket P01's finish pass, from the template
    ``template_text``; the arguments of ``mirror pockets`` for it."""
    shell = Shell()
    (tmp_path / "pocket.nc").write_bytes(template_text.encode())
    (tmp_path / "cal.json").write_text(shell_calibration_text())
    b, z = shell.local_grid()
    (tmp_path / "s.csv").write_text(thickness_csv(shell.machine(0, b, z, -0.3), "semi"))
    (tmp_path / "plan.csv").write_text(plan_csv(shell, [("s.csv", "")]))
    return ["mirror", "pockets", str(tmp_path / "plan.csv"), "-c", str(tmp_path / "cal.json"),
            "--program", str(tmp_path / "pocket.nc"), "--t-ref", "2.0", "--band", "1.98,2.02",
            "--allowance", "0.3", "-o", str(tmp_path / "out")]


def test_a_sinumerik_template_is_checked_and_corrected_as_sinumerik(tmp_path):
    # generic chooses Sinumerik by the program's header, for the check of the template
    # against the maps as for its correction: read as generic, the header is refused
    lines = pocket_program(Shell(), Y_BOTTOM).splitlines()
    assert lines[0] == "%"
    assert lines[-1] == "%"
    body = [";" + ln[1:-1] if ln.startswith("(") else ln for ln in lines[1:-1]]
    text = "\n".join(["%_N_POCKET_MPF", ";$PATH=/_N_WKS_DIR/_N_POCKET_WPD", *body]) + "\n"
    res = CliRunner().invoke(main, _finish_job(tmp_path, text))
    assert res.exit_code == 0, res.output
    out = (tmp_path / "out" / "P01_finish.nc").read_text().splitlines()
    assert out[0] == "%_N_POCKET_MPF"
    assert any(ln.startswith(";POSTPROC ") for ln in out[:6])


def test_the_check_of_the_template_is_bounded_as_its_correction(tmp_path):
    # a loop whose later passes leave the maps: with --max-iterations 100 the check stops
    # at that bound, as the correction would, instead of running every pass
    prog = pocket_program(Shell(), Y_BOTTOM).replace(
        "M30\n", "#1 = 3.75\no1 repeat [400]\n#1 = [#1 + 0.25]\nG1 B#1\no1 endrepeat\nM30\n", 1)
    res = CliRunner().invoke(main, [*_finish_job(tmp_path, prog), "--max-iterations", "100"])
    assert res.exit_code != 0
    assert "--max-iterations" in res.output
    assert "outside the correction map" not in res.output
    assert not (tmp_path / "out").exists()
