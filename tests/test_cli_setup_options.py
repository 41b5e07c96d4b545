"""The setup options (--offset, --tool-length, --tool-table, --tool-vector, --start, --home,
--context) are declared once and mean the same in correct, diff, verify and mirror pockets."""

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from postproc.calfile import save_calibration
from postproc.cli import main
from postproc.cli.options import SETUP_OPTIONS
from postproc.engine.static import StaticEngine

ROOT = Path(__file__).parents[1]
STATIC = str(ROOT / "calibrations" / "s500_static.json")
MACHINE = str(ROOT / "calibrations" / "s500.machine.json")
POCKET = str(ROOT / "samples" / "pocket.nc")
MIRROR = ROOT / "samples" / "mirror"


def commands(tmp_path) -> dict[str, list[str]]:
    """Each command with arguments it runs with (nothing else is wrong with them)."""
    return {
        "correct": ["correct", POCKET, "-c", STATIC, "-o", str(tmp_path / "out.nc")],
        "diff": ["diff", POCKET, POCKET],
        "verify": ["verify", POCKET, "-c", STATIC, "--machine", MACHINE],
        "mirror pockets": ["mirror", "pockets", str(MIRROR / "plan.csv"), "-c", str(MIRROR / "shell_static.json"),
                           "--program", str(MIRROR / "pocket.nc"), "--t-ref", "2.0", "--band", "1.98,2.02",
                           "--allowance", "0.3", "-o", str(tmp_path / "next")],
    }


def command_object(name: str):
    cmd = main.get_command(None, name.split()[0])
    for part in name.split()[1:]:
        cmd = cmd.get_command(None, part)
    return cmd


@pytest.mark.parametrize("name", ["correct", "diff", "verify", "mirror pockets"])
def test_each_command_declares_the_same_setup_options(name):
    cmd = command_object(name)
    declared = {max(p.opts, key=len): p for p in cmd.params if max(p.opts, key=len) in SETUP_OPTIONS}
    expected = [flag for flag in SETUP_OPTIONS if not (name == "diff" and flag == "--context")]
    assert list(declared) == expected
    reference = {max(p.opts, key=len): p for p in command_object("correct").params}
    for flag, p in declared.items():
        ref = reference[flag]
        assert (p.name, p.help, p.metavar, p.multiple) == (ref.name, ref.help, ref.metavar, ref.multiple), flag


BAD = [
    (["--offset", "G54=X100"], "give all of X, Y and Z (missing Y, Z)"),
    (["--offset", "G54=X100,Y50"], "give all of X, Y and Z (missing Z)"),
    (["--offset", "G60=X1,Y2,Z3"], "expected NAME=X..,Y..,Z.."),
    (["--offset", "G54=X1,Q2,Z3"], "'Q2' is not an axis letter and a number"),
    (["--tool-length", "1=abc"], "expected H=L"),
    (["--tool-vector", "0,0"], "--tool-vector must be three numbers"),
    (["--start", "Z1,Z2"], "Z is given twice"),
    (["--start", "A10"], "'A10' is not X, Y or Z and a number"),
    (["--home", "G29=X0"], "expected G28=X..,Y..,Z.."),
    (["--home", "G28=X0", "--home", "G28=Y0"], "G28 is given twice"),
    (["--context", "temp=warm"], "expected NAME=VALUE"),
]


@pytest.mark.parametrize(("extra", "message"), BAD, ids=lambda v: " ".join(v) if isinstance(v, list) else "")
def test_every_command_refuses_the_same_bad_setup_the_same_way(tmp_path, extra, message):
    errors = {}
    for name, args in commands(tmp_path).items():
        if name == "diff" and extra[0] == "--context":
            continue
        result = CliRunner().invoke(main, [*args, *extra])
        assert result.exit_code == 2, (name, result.output)
        errors[name] = result.output.rsplit("Error: ", 1)[1]
        assert message in errors[name], name
    assert len(set(errors.values())) == 1, errors  # word for word the same
    assert not any(tmp_path.iterdir())  # nothing written


def test_a_partial_work_offset_names_the_option(tmp_path):
    """verify --offset G54=X100 used to run with Y = Z = 0; now every command refuses it."""
    for name, args in commands(tmp_path).items():
        result = CliRunner().invoke(main, [*args, "--offset", "G54=X100"])
        assert result.exit_code == 2, name
        assert "Invalid value for --offset: 'G54=X100': give all of X, Y and Z (missing Y, Z)" in result.output, name


def test_a_tool_table_that_cannot_be_read_is_refused_naming_it(tmp_path):
    missing = tmp_path / "none.tbl"
    for name, args in commands(tmp_path).items():
        result = CliRunner().invoke(main, [*args, "--tool-table", str(missing)])
        assert result.exit_code == 3, (name, result.output)
        assert f"{missing}: cannot read tool table" in result.output, name


def verify_json(args: list[str]) -> dict:
    result = CliRunner().invoke(main, ["verify", *args, "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


G54_G43 = str(ROOT / "samples" / "g54_g43.ngc")


def test_verify_takes_tool_lengths_from_a_tool_table(tmp_path):
    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 Z100 D6 ;end mill\nT2 P2 Z80\n")
    common = [G54_G43, "-c", STATIC, "--machine", MACHINE, "--offset", "G54=X100,Y80,Z40"]
    by_length = verify_json([*common, "--tool-length", "1=100"])
    by_table = verify_json([*common, "--tool-table", str(table)])
    assert by_table == by_length
    other = verify_json([*common, "--tool-length", "1=60"])
    assert other["runs"][0]["max_mm"] != by_length["runs"][0]["max_mm"]


# a squareness between Z and X/Y: the machine's Z error depends on X and Y
G_Z = np.array([[1 + 300e-6, 900e-6, -600e-6], [200e-6, 1 - 200e-6, 1000e-6], [700e-6, -500e-6, 1 + 150e-6]])
FLAT = "G21 G90 G17 G94\nG0 X10 Y10\nG1 X60 Y10 F800\nG3 X60 Y50 I0 J20\nG1 X10 Y50\nG2 X10 Y10 R20\nG0 X0 Y0\nM30\n"


@pytest.fixture
def zsq(tmp_path):
    cal = tmp_path / "zsq.json"
    save_calibration(cal, StaticEngine(G_Z, [0.03, -0.02, 0.01], [[-1e4] * 3, [1e4] * 3]), name="zsq")
    return str(cal)


def test_verify_start_runs_a_program_that_never_names_z_as_if_it_did(tmp_path, zsq):
    flat = tmp_path / "flat.nc"
    flat.write_text(FLAT)
    named = tmp_path / "named.nc"  # the same program with Z at the start position named
    named.write_text(FLAT.replace("G0 X10 Y10\n", "G0 X10 Y10 Z150\n"))
    common = ["-c", zsq, "--machine", zsq, "--offset", "G54=X100,Y80,Z0"]
    result = CliRunner().invoke(main, ["verify", str(flat), *common])
    assert result.exit_code == 5, result.output
    assert "--start" in result.output
    started = verify_json([str(flat), *common, "--start", "Z150"])
    explicit = verify_json([str(named), *common])
    assert [r["label"] for r in started["runs"]] == [r["label"] for r in explicit["runs"]]
    for a, b in zip(started["runs"], explicit["runs"], strict=True):
        assert a["max_mm"] == pytest.approx(b["max_mm"], abs=1e-9)
        assert a["rms_mm"] == pytest.approx(b["rms_mm"], abs=1e-9)
    # the Z squareness tilts the uncorrected path by up to 0.7 mrad * 50 mm; the correction removes it
    assert started["runs"][0]["max_mm"] > 0.02
    assert started["runs"][1]["max_mm"] < 0.002


def test_verify_home_gives_the_position_g28_goes_to(tmp_path, zsq):
    body = "G21 G90\nG0 X10 Y10 Z5\nG1 X60 F800\nG91 G28 Z0\nG90\nG0 X20 Y40\nG1 X70 Y45 F800\nM30\n"
    homed = tmp_path / "homed.nc"
    homed.write_text(body)
    machine = tmp_path / "machine.nc"  # G28 Z written as the machine move it makes
    machine.write_text(body.replace("G91 G28 Z0\nG90\n", "G90 G53 G0 Z300\n"))
    common = ["-c", zsq, "--machine", zsq, "--offset", "G54=X100,Y80,Z40"]
    result = CliRunner().invoke(main, ["verify", str(homed), *common])
    assert result.exit_code != 0
    assert "--home" in result.output
    by_home = verify_json([str(homed), *common, "--home", "G28=X0,Y0,Z300"])
    by_g53 = verify_json([str(machine), *common])
    for a, b in zip(by_home["runs"], by_g53["runs"], strict=True):
        assert a["max_mm"] == pytest.approx(b["max_mm"], abs=1e-9)
        assert a["rms_mm"] == pytest.approx(b["rms_mm"], abs=1e-9)


def test_verify_points_refuse_setup_options_they_would_not_use():
    points = str(ROOT / "samples" / "s500_control_points.csv")
    result = CliRunner().invoke(main, ["verify", "--points", points, "-c", STATIC, "--machine", MACHINE,
                                       "--offset", "G54=X1,Y2,Z3", "--start", "Z5"])
    assert result.exit_code == 2
    assert "--points takes machine targets: --offset, --start would not be used" in result.output


def test_diff_setup_options_override_the_header(tmp_path, zsq):
    """A program corrected with --start Z150: diff reads it from the header, and an explicit
    --start gives the same figures; a wrong one gives other figures."""
    src = tmp_path / "flat.nc"
    src.write_text("G21 G90\nG0 X10 Y10\nG1 X60 F800\nG1 Y50\nG1 X10\nG0 X0 Y0\nM30\n")
    out = tmp_path / "flat_corrected.nc"
    res = CliRunner().invoke(main, ["correct", str(src), "-c", zsq, "--offset", "G54=X100,Y80,Z0", "--start", "Z150",
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output

    def axis_stats(*extra):
        r = CliRunner().invoke(main, ["diff", str(src), str(out), "--json", *extra])
        assert r.exit_code == 0, r.output
        return json.loads(r.output)["per_axis"]

    from_header = axis_stats()
    assert axis_stats("--start", "Z150") == from_header
    assert axis_stats("--start", "Z149.9") != from_header


def test_mirror_pockets_takes_the_same_tool_table(tmp_path):
    template = tmp_path / "pocket_h1.nc"
    template.write_text((MIRROR / "pocket.nc").read_text().replace("G21 G90 G94\n", "G21 G90 G94 G43 H1\n"))
    table = tmp_path / "tools.tbl"
    table.write_text("T1 P1 Z100\n")
    args = commands(tmp_path)["mirror pockets"]
    args[args.index("--program") + 1] = str(template)
    out_dir = args.index("-o") + 1
    result = CliRunner().invoke(main, args)
    assert result.exit_code == 5, result.output
    assert "tool length of tool 1" in result.output
    written = []
    for k, extra in enumerate((["--tool-length", "1=100"], ["--tool-table", str(table)], ["--tool-length", "1=50"])):
        run = list(args)
        run[out_dir] = str(tmp_path / f"next{k}")
        result = CliRunner().invoke(main, [*run, *extra])
        assert result.exit_code == 0, result.output
        written.append({p.name: p.read_bytes() for p in Path(run[out_dir]).iterdir()})
    assert written[0] == written[1]
    assert written[0] != written[2]
