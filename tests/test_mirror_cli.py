import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from numpy.testing import assert_allclose

from postproc.cli import main
from postproc.mirror.feedback import read_thickness
from postproc.mirror.maps import load_map
from postproc.mirror.synthetic import Shell

SAMPLES = Path(__file__).parents[1] / "samples" / "mirror"


def run(*args):
    res = CliRunner().invoke(main, ["mirror", *map(str, args)])
    return res


def test_help_of_every_subcommand_has_an_example():
    for sub in ("kdist", "kfb", "pockets", "deadband", "synth"):
        res = run(sub, "--help")
        assert res.exit_code == 0, res.output
        assert "Example:" in res.output


def test_synth_then_kdist_recovers_the_wall(tmp_path):
    assert run("synth", tmp_path).exit_code == 0
    out = tmp_path / "k.csv"
    res = run("kdist", tmp_path / "backwall_sensor.csv", "--cutter-radius", 10, "--diameter", 2000,
              "--segment-deg", 2, "--units", "um", "-o", out)
    assert res.exit_code == 0, res.output
    assert "245 segments" in res.output
    m = load_map(out)
    shell = Shell()
    centres = np.column_stack([np.arange(4.0, 72.0, 2.0), np.full(34, shell.z0_mm + 30)])
    # 20 points of 1 um noise per 2-degree segment: E known to ~0.2 um; the truth is linear in B
    assert_allclose(m.values_at(centres), shell.e_dist(centres[:, 0], centres[:, 1]), atol=1e-3)
    assert m.apply_axis == "Y"
    assert m.sign == 1.0


def test_kfb_is_formula_7(tmp_path):
    out = tmp_path / "kfb.csv"
    res = run("kfb", SAMPLES / "P01_semi.csv", "--t-ref", 2.0, "--allowance", 0.3, "--origin", "3,100",
              "--thinner-direction", "-Y", "-o", out)
    assert res.exit_code == 0, res.output
    m = load_map(out)
    semi = read_thickness(SAMPLES / "P01_semi.csv")
    assert_allclose(m.values_at(np.column_stack([semi.b_deg - 3, semi.z_mm - 100])), semi.t_mm - 2.3,
                    atol=1e-7)
    assert m.sign == -1.0


def test_deadband_reports_plateaus_of_the_gap_and_a_learned_map_removes_them(tmp_path):
    learned = tmp_path / "db.csv"
    trace = tmp_path / "trace.csv"
    res = run("deadband", SAMPLES / "zigzag_sensor.csv", "--gap", 0.02, "--learn", learned, "-o", trace)
    assert res.exit_code == 0, res.output
    travels = [float(x) for x in re.findall(r"input travel ([\d.]+) um", res.output)]
    assert len(travels) == 3
    # the sample step of the signal is under 1 um: the plateau spans the gap to within it
    assert all(19.0 <= t <= 20.0 for t in travels)
    assert "-10.00..+10.00 um" in res.output
    res2 = run("deadband", SAMPLES / "zigzag_sensor.csv", "--gap", 0.02, "--correction", learned)
    assert "residual -0.00..+0.00 um" in res2.output or "residual +0.00..+0.00 um" in res2.output


def test_deadband_plot(tmp_path):
    pytest.importorskip("matplotlib")
    png = tmp_path / "db.png"
    res = run("deadband", SAMPLES / "zigzag_sensor.csv", "--gap", 0.02, "--drive-tau", 0.02, "--plot", png)
    assert res.exit_code == 0, res.output
    assert png.stat().st_size > 10_000


def test_bad_sensor_file_names_its_place(tmp_path):
    bad = tmp_path / "s.csv"
    bad.write_text("B,Z,V\n0,0,0\n1,0,x\n")
    res = run("kdist", bad, "--cutter-radius", 10, "--diameter", 2000, "-o", tmp_path / "k.csv")
    assert res.exit_code == 3
    assert f"{bad}:3:" in res.output
    assert not (tmp_path / "k.csv").exists()


def test_correct_with_a_kfb_map_moves_each_node_by_its_value(tmp_path):
    from postproc.gcode.path import program_path

    kfb = tmp_path / "kfb.csv"
    assert run("kfb", SAMPLES / "P01_semi.csv", "--t-ref", 2.0, "--allowance", 0.3, "--origin", "3,100",
               "-o", kfb).exit_code == 0
    out = tmp_path / "P01_finish.nc"
    res = CliRunner().invoke(main, ["correct", str(SAMPLES / "pocket.nc"), "-c", str(SAMPLES / "shell_identity.json"),
                                    "--map", str(kfb), "-o", str(out)])
    assert res.exit_code == 0, res.output
    pp = program_path(out)
    feed = ~pp.rapid
    semi = read_thickness(SAMPLES / "P01_semi.csv")
    b, z = semi.b_deg - 3.0, semi.z_mm - 100.0
    for bb, zz, t in zip(b, z, semi.t_mm, strict=True):
        hit = np.flatnonzero(feed & (np.abs(pp.context["B"] - bb) < 1e-6) & (np.abs(pp.points_mm[:, 2] - zz) < 1e-6))
        # identity geometry: Y moves by K_fb = T - T_ref - b (4 decimals written)
        assert abs(pp.points_mm[hit[-1], 1] - (-5.0 + t - 2.3)) <= 0.5e-4 + 1e-9
