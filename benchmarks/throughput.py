"""Throughput and peak memory of postproc on a realistic CAM program, against the targets.

The program is made by ``../shared/bench/gencam.py N OUT [SEED]`` (15 % arcs, 20 tools,
comments, N numbers, an O-number header, G28 at the end). Every case runs in its own
child process, --repeats times; the median wall time of the child is printed with the
input lines per second and the child's peak RSS (the largest of the runs):

  (a) read and write the file unchanged (the floor: Python line I/O);
  (b) the tokenizer: ``lex`` every line and write ``tokens_to_src`` (byte-identical);
  (c) ``postproc correct`` with calibrations/s500_static.json; (c1) the same with -j 1;
  (d) ``postproc correct`` with calibrations/s500_parametric.json; (d1) the same with -j 1;
  (e) ``postproc diff ORIGINAL CORRECTED`` (the output of (c));
  (r) LinuxCNC's ``rs274 -g`` on the same program (interpreting only, no correction): the
      rate of "as fast as a controller reads", when rs274 is installed;
  (u) (c) uncompiled: a copy of the tree without the compiled core's *.so files;
  (v) with ``--release TREE`` (a checkout of the last release, e.g. ``git worktree add
      /tmp/release 5b3c58d``): (c) with that tree's package, the baseline of the
      uncompiled target (at least 2/3 of the release's rate on the same run);
  (f) ``postproc --help``;
  (g) a 20-line program corrected with the parametric calibration, end to end;
  (m) ``postproc correct`` static on a --memory-lines program: peak RSS (once);
  (n) ``postproc diff`` of (m)'s input and output: peak RSS (once).

``correct`` runs as a user runs it: a program this large is cut into parts corrected in
one process per core (``postproc.gcode.split``); (c1) and (d1) (``--cases static1,
parametric1``; (c1) by default) run it with ``-j 1``, in one process, for the ratio.

Peak RSS is that of the case's largest process; beside it, the peak of the summed PSS of
all its processes (``diff`` reads large programs in child processes of its own, and
``correct`` splits them in two), sampled every half second from /proc. The memory target
is checked on the larger of the two.

The package's compiled core (setup.py) is used when built; the first lines say whether.
The children import the package from byte-code compiled once, before the timed runs, into
the benchmark's temporary folder (as an installed package is), whatever
PYTHONDONTWRITEBYTECODE says.

(c), (d) and (e) are also given as ratios of (a)'s and (b)'s rates, and each figure
that has a target is printed beside it with PASS or FAIL.

Usage: python benchmarks/throughput.py [--lines N] [--memory-lines N] [--repeats R]
                                       [--seed S] [--json OUT] [--cases static,static1,parametric,diff]
                                       [--release TREE]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GENCAM = ROOT.parent / "shared" / "bench" / "gencam.py"
STATIC = ROOT / "calibrations" / "s500_static.json"
PARAMETRIC = ROOT / "calibrations" / "s500_parametric.json"

# The setup a gencam program needs: G54, tool lengths for T1..T20 and the G28 position,
# chosen so that every move stays inside the S500 calibrations' volume [0, 315]^3 mm.
SETUP = ["--offset", "G54=X0,Y0,Z100", "--home", "G28=X0,Y0,Z200",
         *[arg for t in range(1, 21) for arg in ("--tool-length", f"{t}=0")]]

# the targets: (what, test on the figure, text)
TARGETS = {
    "static": (lambda r: r >= 250_000, ">= 250,000 lines/s"),
    "static1": (lambda r: r >= 150_000, ">= 150,000 lines/s"),
    "parametric": (lambda r: r >= 60_000, ">= 60,000 lines/s"),
    "diff": (lambda r: r >= 300_000, ">= 300,000 lines/s"),
    "rss": (lambda mb: mb <= 150.0, "<= 150 MB"),
    "help": (lambda s: s <= 0.25, "<= 0.25 s"),
    "job20": (lambda s: s <= 0.8, "<= 0.8 s"),
}

CHILD = r"""
import sys
case, src, dst = sys.argv[1:4]
if case == "copy":
    with open(src, encoding="utf-8", newline="") as fi, open(dst, "w", encoding="utf-8", newline="") as fo:
        for line in fi:
            fo.write(line)
else:
    from postproc.gcode.lexer import lex, tokens_to_src
    with open(src, encoding="utf-8", newline="") as fi, open(dst, "w", encoding="utf-8", newline="") as fo:
        for line in fi:
            fo.write(tokens_to_src(lex(line)))
"""


# The children import postproc from byte-code cached in the benchmark's own folder (set in
# main), as an installed package does: a shell with PYTHONDONTWRITEBYTECODE set would
# otherwise compile every module of the package on each run (about 0.3 s a run).
CHILD_ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}


def tree_memory(pid: int) -> float:
    """Summed PSS (MB) of process ``pid`` and its children, the memory they take together
    (shared pages counted once); 0 where /proc does not tell."""
    kb = 0
    try:
        kids = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        kids = []
    for q in [str(pid), *kids]:
        try:
            for row in Path(f"/proc/{q}/smaps_rollup").read_text().splitlines():
                if row.startswith("Pss:"):
                    kb += int(row.split()[1])
                    break
        except OSError:
            pass
    return kb / 1024.0


def run_child(cmd: list[str], log: Path) -> tuple[float, float, float]:
    """Run ``cmd`` (cwd: the repository, so that its own postproc is imported): wall
    seconds, the peak RSS of its largest process in MB and the peak summed PSS of its
    processes. A failing child stops the benchmark.

    The wall time ends when the child exits: this thread waits for it (``wait4``, which
    also gives its peak RSS), while another samples the PSS of it and its children
    (``diff`` reads large programs in child processes) every 0.05 s for the first second
    and every 0.5 s after, without delaying the end of the measurement."""
    with open(log, "wb") as out:
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                env=CHILD_ENV)
        done = threading.Event()
        pss = [0.0]

        def sample() -> None:
            while not done.is_set():
                pss[0] = max(pss[0], tree_memory(proc.pid))
                done.wait(0.5 if time.perf_counter() - t0 > 1.0 else 0.05)

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        _pid, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        done.set()
        sampler.join()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        sys.exit(f"benchmark case failed (exit code {proc.returncode}): {' '.join(cmd)}\n"
                 + log.read_text(errors="replace")[-2000:])
    return wall, usage.ru_maxrss / 1024.0, pss[0]


def measure(cmd: list[str], repeats: int, log: Path) -> dict:
    runs = [run_child(cmd, log) for _ in range(repeats)]
    walls = [w for w, _, _ in runs]
    return {"seconds": statistics.median(walls), "seconds_min": min(walls), "seconds_max": max(walls),
            "peak_mb": max(mb for _, mb, _ in runs), "peak_pss_mb": max(p for _, _, p in runs), "repeats": repeats}


def gencam(n: int, out: Path, seed: int) -> int:
    subprocess.run([sys.executable, str(GENCAM), str(n), str(out), str(seed)], check=True, stdout=subprocess.DEVNULL)
    with open(out, encoding="utf-8", newline="") as fh:
        return sum(1 for _ in fh)


def verdict(key: str, value: float) -> str:
    test, text = TARGETS[key]
    return f"target {text}: {'PASS' if test(value) else 'FAIL'}"


def machine() -> str:
    model = platform.processor() or platform.machine()
    try:
        for row in Path("/proc/cpuinfo").read_text().splitlines():
            if row.startswith("model name"):
                model = row.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}; load average {load}"


def case_line(key: str, label: str, r: dict, rates: dict) -> str:
    """The printed figures of a timed case, with its ratios and verdicts."""
    rate = r["lines_per_s"]
    line = (f"{label:38s} {rate:11,.0f} lines/s  {r['seconds']:7.2f} s  "
            f"(min {r['seconds_min']:.2f}, max {r['seconds_max']:.2f})  peak RSS {r['peak_mb']:6.1f} MB"
            f"  (all processes: PSS {r['peak_pss_mb']:.1f} MB)")
    if key in ("static1", "parametric1") and key[:-1] in rates:
        line += f"\n{'':38s} ({'c' if key == 'static1' else 'd'}) is {rates[key[:-1]] / rate:.2f} x this rate"
    if key in ("static", "static1", "parametric", "diff"):
        mem = max(r["peak_mb"], r["peak_pss_mb"])
        line += (f"\n{'':38s} = {rate / rates['copy']:.4f} x (a), {rate / rates['lex']:.3f} x (b);  "
                 f"{verdict(key, rate)};  memory {verdict('rss', mem)}")
    if key == "rs274" and "static" in rates:
        line += f"\n{'':38s} (c) is {rates['static'] / rate:.2f} x rs274's rate (target: at least 1)"
    if key == "pure" and "static" in rates:
        line += f"\n{'':38s} (c) uncompiled is {rate / rates['static']:.2f} x (c) compiled"
    if key == "release" and "pure" in rates:
        ratio = rates["pure"] / rate
        line += (f"\n{'':38s} (u) is {ratio:.2f} x the release's rate (target: at least 0.67): "
                 + ("PASS" if ratio >= 2 / 3 else "FAIL"))
    return line


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=1_000_000, help="lines of the speed program [1,000,000]")
    ap.add_argument("--memory-lines", type=int, default=5_000_000,
                    help="lines of the program whose static correction and diff give the peak RSS (0: skip) "
                         "[5,000,000]")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each case; the median is printed [3]")
    ap.add_argument("--seed", type=int, default=42, help="gencam.py seed [42]")
    ap.add_argument("--json", dest="json_out", default=None, help="also save the figures to this JSON file")
    ap.add_argument("--cases", default="static,static1,parametric,diff,rs274,pure",
                    help="which of static, static1, parametric, parametric1, diff, rs274, pure to time (static1 "
                         "and parametric1: in one process, -j 1; pure: static uncompiled; (a) and (b) "
                         "always run; diff needs static's output, made untimed when static is left out) "
                         "[static,static1,parametric,diff,rs274,pure]")
    ap.add_argument("--release", default=None, metavar="TREE",
                    help="a checkout of the last release: (v) times its static correction, after (u)")
    args = ap.parse_args()
    chosen = {c.strip() for c in args.cases.split(",") if c.strip()}
    if args.release:
        chosen.add("release")
    known = {"static", "static1", "parametric", "parametric1", "diff", "rs274", "pure", "release"}
    if not chosen <= known:
        sys.exit("--cases takes " + ", ".join(sorted(known)))
    if not GENCAM.is_file():
        sys.exit(f"{GENCAM} is missing: this benchmark needs the shared folder beside the repository "
                 "(../shared/bench/gencam.py makes its program)")
    if args.lines < 1000 or args.repeats < 1 or args.memory_lines < 0:
        sys.exit("--lines must be at least 1000, --repeats at least 1, --memory-lines 0 or more")
    py = sys.executable
    cli = [py, "-m", "postproc"]
    figures: dict = {"machine": machine(), "lines": args.lines, "repeats": args.repeats, "seed": args.seed,
                     "cases": {}}
    print(f"machine: {figures['machine']}")
    # which of the lane's hot modules run compiled (setup.py); run a copy of the tree
    # without its *.so files for the uncompiled figures
    version = subprocess.run([*cli, "--version"], cwd=ROOT, capture_output=True, text=True, env=CHILD_ENV)
    figures["core"] = version.stdout.strip()
    print(f"postproc: {figures['core']}")
    with tempfile.TemporaryDirectory(prefix="postproc-bench-") as tmp:
        tmp = Path(tmp)
        log = tmp / "child.log"
        CHILD_ENV["PYTHONPYCACHEPREFIX"] = str(tmp / "pycache")
        small = tmp / "job20.nc"
        n20 = gencam(20, small, args.seed)
        for cal in (STATIC, PARAMETRIC):  # untimed: compiles what the timed cases import
            run_child([*cli, "correct", str(small), "-c", str(cal), "-o", str(tmp / "warm.nc"),
                       *SETUP], log)
        run_child([*cli, "diff", str(small), str(tmp / "warm.nc")], log)
        run_child([*cli, "--help"], log)
        src = tmp / "gencam.nc"
        t0 = time.perf_counter()
        n = gencam(args.lines, src, args.seed)
        print(f"program: gencam.py {args.lines} (seed {args.seed}): {n:,} lines, {src.stat().st_size / 1e6:.1f} MB "
              f"(made in {time.perf_counter() - t0:.1f} s); median of {args.repeats} runs per case")
        static_out = tmp / "static.nc"
        pure = tmp / "pure"  # the same tree without the compiled core
        if "pure" in chosen:
            shutil.copytree(ROOT / "postproc", pure / "postproc", ignore=shutil.ignore_patterns("*.so", "__pycache__"))
        pure_cmd = [py, "-c", f"import sys; sys.path.insert(0, {str(pure)!r}); from postproc.cli import main; "
                    "sys.argv[0] = 'postproc'; main()"]
        if "pure" in chosen:  # untimed: compiles the uncompiled tree's byte code
            run_child([*pure_cmd, "correct", str(small), "-c", str(STATIC), "-o", str(tmp / "warm.nc"), *SETUP], log)
        release = str(Path(args.release or ".").resolve())
        release_cmd = [py, "-c", f"import sys; sys.path.insert(0, {release!r}); from postproc.cli import main; "
                       "sys.argv[0] = 'postproc'; main()"]
        if args.release:  # untimed: compiles the release's byte code
            run_child([*release_cmd, "correct", str(small), "-c", str(STATIC), "-o", str(tmp / "warm.nc"), *SETUP],
                      log)
        tools = tmp / "tools.tbl"
        tools.write_text("".join(f"T{t} P{t} Z0 D6\n" for t in range(1, 21)))
        rs274 = shutil.which("rs274")
        cases = [
            ("copy", "(a) read + write unchanged", [py, "-c", CHILD, "copy", str(src), str(tmp / "copy.nc")]),
            ("lex", "(b) tokenizer (lex + tokens_to_src)", [py, "-c", CHILD, "lex", str(src), str(tmp / "lex.nc")]),
            ("static", "(c) correct, s500_static", [*cli, "correct", str(src), "-c", str(STATIC),
                                                    "-o", str(static_out), *SETUP]),
            ("static1", "(c1) correct, s500_static, -j 1", [*cli, "correct", str(src), "-c", str(STATIC),
                                                            "-o", str(tmp / "static1.nc"), "-j", "1", *SETUP]),
            ("parametric", "(d) correct, s500_parametric", [*cli, "correct", str(src), "-c", str(PARAMETRIC),
                                                            "-o", str(tmp / "parametric.nc"), *SETUP]),
            ("parametric1", "(d1) correct, s500_parametric, -j 1",
             [*cli, "correct", str(src), "-c", str(PARAMETRIC), "-o", str(tmp / "parametric1.nc"), "-j", "1",
              *SETUP]),
            ("diff", "(e) diff original (c)-output", [*cli, "diff", str(src), str(static_out)]),
            ("rs274", "(r) LinuxCNC rs274 -g (no correction)",
             [rs274 or "rs274", "-t", str(tools), "-g", str(src), str(tmp / "rs274.txt")]),
            ("pure", "(u) correct, s500_static, uncompiled", [*pure_cmd, "correct", str(src), "-c", str(STATIC),
                                                             "-o", str(tmp / "pure.nc"), *SETUP]),
            ("release", "(v) correct, s500_static, release", [*release_cmd, "correct", str(src), "-c", str(STATIC),
                                                             "-o", str(tmp / "release.nc"), *SETUP]),
        ]
        rates = {}
        for key, label, cmd in cases:
            if key == "rs274" and not rs274:
                print("(r) rs274 is not installed: skipped")
                continue
            if key not in ("copy", "lex") and key not in chosen:
                if key == "static" and "diff" in chosen:
                    run_child(cmd, log)  # the corrected program diff compares
                continue
            r = measure(cmd, args.repeats, log)
            r["lines_per_s"] = rate = n / r["seconds"]
            rates[key] = rate
            figures["cases"][key] = r
            line = case_line(key, label, r, rates)
            print(line, flush=True)

        r = measure([*cli, "--help"], max(args.repeats, 5), log)
        figures["cases"]["help"] = r
        print(f"{'(f) postproc --help':38s} {r['seconds']:7.3f} s wall   peak RSS {r['peak_mb']:6.1f} MB  "
              + verdict("help", r["seconds"]), flush=True)

        r = measure([*cli, "correct", str(small), "-c", str(PARAMETRIC), "-o", str(tmp / "job20_out.nc"), *SETUP],
                    max(args.repeats, 5), log)
        figures["cases"]["job20"] = r
        print(f"{f'(g) {n20}-line parametric job':38s} {r['seconds']:7.3f} s wall   peak RSS {r['peak_mb']:6.1f} MB  "
              + verdict("job20", r["seconds"]), flush=True)

        if args.memory_lines:
            big = tmp / "memory.nc"
            src.unlink()  # room on the disk for the big program and its output
            nm = gencam(args.memory_lines, big, args.seed)
            out = tmp / "memory_out.nc"
            for key, label, cmd in (
                ("memory", f"(m) correct static, {nm:,} lines",
                 [*cli, "correct", str(big), "-c", str(STATIC), "-o", str(out), *SETUP]),
                ("memory_diff", f"(n) diff of (m), {nm:,} lines", [*cli, "diff", str(big), str(out)]),
            ):
                r = measure(cmd, 1, log)
                r["lines"] = nm
                r["lines_per_s"] = nm / r["seconds"]
                figures["cases"][key] = r
                print(f"{label:38s} {r['lines_per_s']:11,.0f} lines/s  "
                      f"{r['seconds']:7.2f} s  peak RSS {r['peak_mb']:6.1f} MB  (all processes: PSS "
                      f"{r['peak_pss_mb']:.1f} MB)  " + verdict("rss", max(r["peak_mb"], r["peak_pss_mb"])),
                      flush=True)
    if args.json_out:
        Path(args.json_out).write_text(json.dumps(figures, indent=2) + "\n")
        print(f"figures saved to {args.json_out}")


if __name__ == "__main__":
    main()
