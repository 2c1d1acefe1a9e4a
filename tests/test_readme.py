"""What README.md says is true: its commands parse and run, its Python runs, its numbers hold.

Everything is read from README.md at test time, so a section added later is checked too:

* every ``rrr-pin`` command of a fenced ``sh``/``bash`` block parses with the real parser
  (``rrr_pin.cli.build_parser``), and the concrete ones (no ``[...]``, ``|`` or ``...``) run
  for real, in-process, in a temporary folder, with the small overrides of :data:`SHRINK`
  (their README settings take minutes); :data:`PARSE_ONLY` names the ones that only parse, and
  why. A synopsis line, and every inline ``rrr-pin ...`` span of the prose, must name only
  options its sub-command has;
* ``make`` targets, ``scripts/*.py`` paths, the ``test`` extra and the ``slow`` marker that the
  shell blocks use exist;
* every fenced ``python`` block (of README.md and docs/*.md) is executed, except those of
  :data:`COMPILE_ONLY` (too slow: compiled, with the reason); the inline ``rrr-pin`` spans of
  docs/*.md name real options too;
* the numbers the README states that take seconds to recompute are recomputed (the design,
  the analysis block's comments, the nominal tracking errors, the off-reference bound, the
  built-in laws, robot names, the layer table, Pinocchio against the closed form). Each is
  read from the README's text by a pattern, so a reworded claim fails here until its check is
  updated. Not recomputed: the test count (collecting the suite alone takes longer than this
  whole file), the timings, and the uncertain-plant, Monte Carlo, stress and UR5/Panda tables
  (minutes each; ``tests/test_slow.py`` and the scripts reproduce them).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import math
import re
import shlex
import shutil
from pathlib import Path

import numpy as np
import pytest
import tomllib

from rrr_pin import cli
from rrr_pin.cli.common import negative_values, parse_lock

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
#: The other documents: their Python blocks run and their rrr-pin spans name real options too.
DOCS = {p.relative_to(ROOT).as_posix(): p.read_text() for p in sorted(ROOT.glob("docs/*.md"))}

#: Options added to a README command of that sub-command before it runs (argparse keeps the
#: last value of an option, so these override the README's own): the README's settings take
#: minutes (10 plants, 4-10 s runs, 1000 plants); these take seconds and run the same code.
SHRINK = {
    "montecarlo": ["--samples", "1", "--duration", "0.2", "--jobs", "1", "--overwrite",
                   "--no-progress"],
    "stress": ["--controllers", "fl", "--duration", "0.2"],
    "identify": ["--maxiter", "2", "--overwrite"],
}

#: README commands that only parse: a word of the command (sub-command or option), and why it
#: does not run here.
PARSE_ONLY = {
    "--scheduler": "needs a running Dask scheduler",
    "--resume": "needs an interrupted campaign",
    # even shrunk to 1 plant x 0.2 s, its 6 figures and report.html cost ~25 s of CPU;
    # tests/test_cli.py runs it small, and test_reproduce_arms_load below loads each arm
    "reproduce": "its figures take ~25 s even shrunk",
    "--data": "needs a measured log (scripts/identify_example.py writes one)",
    "--uncertainty": "needs an identification.json (rrr-pin identify writes one)",
    "hil": "needs an exported folder, and runs for minutes; tests/test_hil.py runs it",
    "--tune-lam": "a tuning against three requirements on 21 plants with its simulations "
                  "takes minutes; tests/test_tuning.py runs rrr-pin design small",
    "--per-joint-lam": "a tuning of six parameters on 21 plants takes a minute; "
                       "tests/test_per_joint_lam.py runs it small",
}

#: Python blocks (named by a line they hold) that are compiled, not run, and why.
COMPILE_ONLY = {
    "class ComputedTorquePD": "the full study with a Python-engine law on 10 plants (~15 s)",
    "parametric_margin(law, q": "robstab on the frozen 10 x 10 loop (~1 min); the slow test "
                                "of tests/test_analysis.py checks its margins",
    'build("controller_c")': "a CMake build (tests/test_export.py compiles an export)",
}


# --- reading the README ----------------------------------------------------------------------

def fenced_blocks(text: str) -> list[tuple[str, str, int]]:
    """``(language, code, first line number)`` of every fenced block."""
    out, lines, i = [], text.splitlines(), 0
    while i < len(lines):
        m = re.match(r"^```([^`\s]*)", lines[i])  # ```python, ```, or MyST's ```{include}
        if m:
            start, i = i + 1, i + 1
            while not lines[i].startswith("```"):
                i += 1
            out.append((m.group(1), "\n".join(lines[start:i]), start + 1))
        i += 1
    return out


def shell_commands() -> list[tuple[list[str], int]]:
    """Every command of the ``sh``/``bash`` blocks, as tokens, with its line number.

    Comments are dropped, ``&&`` splits commands, and an indented line continues the command
    above it (the synopsis lines of the command-line section).
    """
    out = []
    for lang, code, first in fenced_blocks(README):
        if lang not in ("sh", "bash", "shell", "console"):
            continue
        for n, line in enumerate(code.splitlines()):
            tokens = shlex.split(line, comments=True)
            if not tokens:
                continue
            if line[:1].isspace() and out:
                out[-1][0].extend(tokens)
                continue
            for part in " ".join(shlex.quote(t) for t in tokens).split(" && "):
                out.append((shlex.split(part), first + n))
    return out


def rrr_pin_commands():
    return [(t[1:], line) for t, line in shell_commands() if t[0] == "rrr-pin"]


def inline_rrr_pin(text: str = README) -> list[str]:
    """Inline code spans of the prose that are ``rrr-pin`` commands (fenced blocks excluded)."""
    prose = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return [s for s in re.findall(r"`([^`\n]+)`", prose.replace("\n", " "))
            if s.startswith("rrr-pin ")]


def is_synopsis(argv: list[str]) -> bool:
    return any(c in " ".join(argv) for c in ("[", "|", "..."))


PARSER = cli.build_parser()
SUBCOMMANDS = next(a for a in PARSER._actions
                   if isinstance(a, argparse._SubParsersAction)).choices


def options_of(command: str) -> set[str]:
    return set(SUBCOMMANDS[command]._option_string_actions)


def unknown_options(argv: list[str]) -> list[str]:
    """Options of a (synopsis) command line that its sub-command does not have."""
    words = [w.split("=")[0] for w in re.findall(r"--[a-z][a-z0-9-]*(?:=\S+)?", " ".join(argv))]
    return [w for w in words if w not in options_of(argv[0])]


def claim(pattern: str, text: str = README) -> tuple[str, ...]:
    """The groups of the README's one match of ``pattern`` (whitespace-tolerant)."""
    found = re.findall(pattern.replace(" ", r"\s+"), text)
    assert len(found) == 1, f"README: expected one match of {pattern!r}, found {len(found)}"
    return found[0] if isinstance(found[0], tuple) else (found[0],)


# --- commands --------------------------------------------------------------------------------

def test_the_readme_has_commands_and_code():
    # the parsing above finds what is there (so the tests below check something)
    langs = [lang for lang, _, _ in fenced_blocks(README)]
    assert langs.count("python") >= 3 and len(rrr_pin_commands()) >= 10
    assert len(inline_rrr_pin()) >= 5


@pytest.mark.parametrize("argv, line", rrr_pin_commands(),
                         ids=[f"line{line}" for _, line in rrr_pin_commands()])
def test_fenced_command_parses(argv, line):
    assert argv[0] in SUBCOMMANDS, f"README line {line}: no sub-command {argv[0]!r}"
    assert unknown_options(argv) == [], f"README line {line}: rrr-pin {' '.join(argv)}"
    if not is_synopsis(argv):
        try:
            PARSER.parse_args(negative_values(argv))
        except SystemExit:
            pytest.fail(f"README line {line}: `rrr-pin {' '.join(argv)}` does not parse")


INLINE = inline_rrr_pin() + [s for text in DOCS.values() for s in inline_rrr_pin(text)]


@pytest.mark.parametrize("span", INLINE)
def test_inline_command_names_real_options(span):
    argv = span.split()[1:]
    assert argv[0] in SUBCOMMANDS, f"README: `{span}`: no sub-command {argv[0]!r}"
    assert unknown_options(argv) == [], f"README: `{span}`"


def runnable():
    out = []
    for argv, line in rrr_pin_commands():
        if is_synopsis(argv) or any(o in argv for o in PARSE_ONLY):
            continue
        out.append((argv, line))
    return out


@pytest.mark.parametrize("argv, line", runnable(), ids=[f"line{n}" for _, n in runnable()])
def test_fenced_command_runs(argv, line, tmp_path, monkeypatch, capsys, strict_json):
    shutil.copytree(ROOT / "urdf", tmp_path / "urdf")  # as in a clone (urdf --check)
    monkeypatch.chdir(tmp_path)
    refused = "# refused" in README.splitlines()[line - 1]  # shrinking could make it valid
    code = cli.main(argv + ([] if refused else SHRINK.get(argv[0], [])))
    out, err = capsys.readouterr()
    if refused:
        # a command the README shows being refused: a clear message, no traceback, exit 2
        assert code == 2 and "error:" in err and "Traceback" not in err, \
            f"README line {line}: `rrr-pin {' '.join(argv)}` was not refused: {code} {err}"
        return
    assert code == 0, f"README line {line}: `rrr-pin {' '.join(argv)}` exited {code}: {err}"
    if "--json" in argv:
        strict_json(out)


def test_parse_only_commands_are_known():
    # every command that only parses is named here with its reason, none silently skipped
    skipped = [argv for argv, _ in rrr_pin_commands()
               if not is_synopsis(argv) and (argv, _) not in runnable()]
    assert all(any(o in argv for o in PARSE_ONLY) for argv in skipped)


def reproduce_commands():
    return [(argv, n) for argv, n in rrr_pin_commands()
            if argv[0] == "reproduce" and not is_synopsis(argv)]


@pytest.mark.parametrize("argv, line", reproduce_commands(),
                         ids=[f"line{n}" for _, n in reproduce_commands()])
def test_reproduce_arms_load(argv, line):
    # what of a parse-only `rrr-pin reproduce` depends on the README: its arm and locked joints
    from rrr_pin.model.dynamics import load_robot

    args = PARSER.parse_args(argv)
    robot = load_robot(args.robot, lock=parse_lock(args.lock))
    assert robot.nq >= 1, f"README line {line}"


def test_other_shell_commands_name_what_exists():
    makefile = (ROOT / "Makefile").read_text()
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    markers = " ".join(pyproject["tool"]["pytest"]["ini_options"]["markers"])
    texts = [" ".join(t) for t, _ in shell_commands()] + re.findall(r"`([^`\n]+)`", README)
    for text in texts:
        tokens = text.split()
        if tokens[:1] == ["make"]:
            for target in tokens[1:]:
                assert re.search(rf"^{re.escape(target)}:", makefile, re.M), f"make {target}"
        for path in re.findall(r"\bscripts/\w+\.py\b", text):
            assert (ROOT / path).is_file(), path
        for extra in re.findall(r"\.\[(\w+)\]", text):
            assert extra in pyproject["project"]["optional-dependencies"], text
        for marker in re.findall(r"pytest -m (\w+)", text):
            assert f"{marker}:" in markers, text
    # what the quick start says the two make targets run
    assert re.search(r"^reproduce:.*\n\t\$\(BIN\)/rrr-pin reproduce", makefile, re.M)
    assert re.search(r"^test:.*\n\t\$\(BIN\)/python -m pytest -n 2$", makefile, re.M)


# --- Python blocks ---------------------------------------------------------------------------

PYTHON = [(name, code, first) for name, text in {"README.md": README, **DOCS}.items()
          for lang, code, first in fenced_blocks(text) if lang == "python"]


@pytest.mark.parametrize("name, code, line", PYTHON, ids=[f"{n}:{i}" for n, _, i in PYTHON])
def test_python_block(name, code, line, tmp_path, monkeypatch):
    compiled = compile(code, f"{name}:{line}", "exec")
    if any(key in code for key in COMPILE_ONLY):
        return  # compiled only (COMPILE_ONLY says why)
    monkeypatch.chdir(tmp_path)
    with contextlib.redirect_stdout(io.StringIO()):
        exec(compiled, {"__name__": "__readme__"})


# --- numbers ---------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def d():
    import rrr_pin

    return rrr_pin.design()


def digits(text: str) -> float:
    """The precision of a number as printed: half a unit of its last digit."""
    mantissa = text.lower().split("e")[0]
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    exponent = int(text.lower().split("e")[1]) if "e" in text.lower() else 0
    return 0.5 * 10.0 ** (exponent - decimals)


def assert_printed(value: float, text: str, what: str) -> None:
    """``value`` rounds to ``text`` (the README's digits), with a 1 % slack on the last digit."""
    assert abs(value - float(text)) <= 1.01 * digits(text), f"{what}: {value} vs README {text}"


def test_design_numbers(d):
    gamma_min, emax = claim(r"gamma_min = \*\*([\d.]+)\*\* \(paper [\d.]+\), "
                            r"emax = \*\*([\d.]+)\*\*")
    assert_printed(d.ncf.gamma_min, gamma_min, "gamma_min")
    assert_printed(d.ncf.emax, emax, "emax")
    k, z1, z2, p1, p2 = claim(r"K\(s\) = ([\d.]+) \(s \+ ([\d.]+)\)\(s \+ ([\d.]+)\) / "
                              r"\(\(s \+ ([\d.]+)\)\(s \+ ([\d.]+)\)\)")
    from rrr_pin.robust.loopshaping import zpk_data

    gain, zeros, poles = zpk_data(d.K_reduced)
    assert_printed(gain, k, "gain of K")
    for got, text in zip(sorted(-np.real(zeros)), sorted([z1, z2], key=float), strict=True):
        assert_printed(got, text, "zero of K")
    for got, text in zip(sorted(-np.real(poles)), sorted([p1, p2], key=float), strict=True):
        assert_printed(got, text, "pole of K")
    change, = claim(r"The reduction changes gamma by \+([\d.]+) %")
    assert_printed(100 * (d.gamma_reduced / d.ncf.gamma - 1), change, "gamma change [%]")
    rs_db, rs_w = claim(r"Robust stability: satisfied, smallest margin ([\d.]+) dB at (\d+) rad/s")
    rs = d.robust_stability.as_dict()
    assert rs["ok"]
    assert_printed(rs["margin_db"], rs_db, "RS margin [dB]")
    assert_printed(rs["worst_frequency"], rs_w, "RS frequency [rad/s]")
    rp_db, rp_w = claim(r"not achievable \(the barriers cross at \d+ rad/s\), (-[\d.]+) dB at "
                        r"(\d+) rad/s")
    rp = d.robust_performance.as_dict()
    assert not rp["ok"]
    assert_printed(rp["margin_db"], rp_db, "RP margin [dB]")
    assert_printed(rp["worst_frequency"], rp_w, "RP frequency [rad/s]")


def test_analysis_block_comments(d):
    import control

    import rrr_pin
    from rrr_pin.robust.loopshaping import fl_plant, lag_weight

    b, gamma = claim(r"rrr_pin.ncfmargin\(d.Gs, d.ncf.Ks\) +# b\(Gs, Ks\) = ([\d.]+) = 1/gamma, "
                     r"gamma = ([\d.]+), at every w")
    got = rrr_pin.ncfmargin(d.Gs, d.ncf.Ks)
    assert_printed(got[0], b, "b(Gs, Ks)")
    assert_printed(1 / got[0], gamma, "1/b")
    # "at every w": the optimal loop's largest singular value is flat (all-pass), at 1/b
    from rrr_pin.robust.ncf import ncf_loop

    loop = ncf_loop(d.Gs, d.ncf.Ks)
    for w in np.logspace(-1, 6, 8):
        peak = np.linalg.svd(np.atleast_2d(loop(1j * w)), compute_uv=False)[0]
        assert peak == pytest.approx(1 / got[0], rel=1e-12)  # measured: 1e-15
    b0, = claim(r"rrr_pin.ncfmargin\(d.G, d.K\) +# \(([\d.]+), inf\)")
    got = rrr_pin.ncfmargin(d.G, d.K)
    assert_printed(got[0], b0, "b(G, K)")
    assert got[1] == math.inf
    gap, nugap = claim(r"fl_plant\(45.0, 3\)\) +# \(([\d.]+), ([\d.]+)\): gap, nu-gap")
    got = rrr_pin.gapmetric(fl_plant(40.0, 3), fl_plant(45.0, 3))
    assert_printed(got[0], gap, "gap")
    assert_printed(got[1], nugap, "nu-gap")
    G = fl_plant(45.0, 1)
    gamma_d, = claim(r"1e-3, \"tustin\"\)\) +# gamma ([\d.]+)")
    syn = rrr_pin.ncfsyn(control.c2d(G, 1e-3), control.c2d(lag_weight(), 1e-3, "tustin"))
    assert_printed(syn.gamma, gamma_d, "discrete ncfsyn gamma")


def test_nominal_tracking_errors():
    import rrr_pin

    fl, hinf = claim(r"max abs error: FL ([\d.e+-]+) rad, H-inf\+FL ([\d.e+-]+) rad \| agrees: "
                     r"both")
    robot = rrr_pin.load_robot("rrr")
    ref = rrr_pin.default_reference(robot)
    laws = rrr_pin.make_laws("fl,hinf", robot)
    errs = [np.max(np.abs(rrr_pin.simulate(robot, law, ref, 4.0).error)) for law in laws]
    # integrator noise: the engines agree to 1e-9 rad, not to 3 digits of a 1e-10 rad number;
    # the claim is the order of magnitude and "both below 5e-06 rad"
    for got, text in zip(errs, (fl, hinf), strict=True):
        assert 0.5 < got / float(text) < 2.0, (got, text)
        assert got < 5e-6
    s_fl, s_hinf = claim(r"the sampling error itself on the exact model \(max ([\d.e+-]+) rad "
                         r"for FL alone, ([\d.e+-]+) rad for H-infinity \+ FL\)")
    sampled = [np.max(np.abs(rrr_pin.simulate(robot, law, ref, 4.0, rate=1000.0).error))
               for law in laws]
    for got, text in zip(sampled, (s_fl, s_hinf), strict=True):
        assert_printed(got, text, "sampled max error [rad]")


def test_off_reference_bound():
    import rrr_pin

    bound, measured, fine = claim(r"per joint: to ([\d.e+-]+) rad at the default 1 ms step\s*"
                                  r"\(([\d.e+-]+) measured, RK4's error with `lam dt = 0.1`\) "
                                  r"and to ([\d.e+-]+) rad at 0.1 ms")
    robot = rrr_pin.load_robot("rrr")
    law, ref = rrr_pin.fl_controller(robot), rrr_pin.default_reference(robot)
    r0, rd0, _ = ref(0.0)
    e0, ed0 = np.array([0.02, -0.01, 0.015]), np.array([0.5, 0.2, -0.3])
    worst = {}
    for dt in (1e-3, 1e-4):
        traj = rrr_pin.simulate(robot, law, ref, 0.1, dt=dt, q0=r0 - e0, qd0=rd0 - ed0)
        t = traj.t[:, None]
        closed = (e0 + (law.lam * e0 + ed0) * t) * np.exp(-law.lam * t)
        worst[dt] = np.max(np.abs(traj.error - closed))
    assert law.lam * 1e-3 == pytest.approx(0.1)
    assert worst[1e-3] <= float(bound) and worst[1e-4] <= float(fine)
    assert_printed(worst[1e-3], measured, "off-reference error at 1 ms [rad]")


def test_builtin_laws_and_robot_names():
    from rrr_pin.control.catalog import LAWS
    from rrr_pin.model.robots import robot_names

    default, = claim(r"rrr-pin reproduce \[--robot NAME\|PATH\] \[--lock JOINT=VALUE \.\.\.\] "
                     r"\[--controllers ([a-z0-9_,]+)\]")
    assert default.split(",") == list(LAWS)
    builtins = claim(r"The built-ins are `(\w+)` \(eq. 20\),\s+`(\w+)` \(eq. 8-10, 18-19\) and "
                     r"`(\w+)`")
    import rrr_pin

    for name in builtins:
        assert callable(getattr(rrr_pin, name))
    names, = claim(r"an example-robot-data name \(((?:`\w+`, )+)\.\.\.\)")
    assert set(re.findall(r"`(\w+)`", names)) <= set(robot_names())


def test_gravity_and_pinocchio_against_the_closed_form():
    from rrr_pin.model.closed_form import compare_with_pinocchio
    from rrr_pin.model.dh import paper_params
    from rrr_pin.model.dynamics import load_robot

    g, = claim(r"gravity ([\d.]+) m/s\^2 \(the paper's\) along `-z`")
    robot = load_robot("rrr")
    assert robot.gravity == float(g)
    rel, = claim(r"agree on `M`, `V`\s+and `G` to ([\d.e-]+) relative on random states")
    result = compare_with_pinocchio(robot, paper_params(), samples=200, seed=0)
    assert max(result[k]["rel"] for k in ("M", "V", "G")) <= float(rel)


def test_layer_table_lists_every_module():
    rows = re.findall(r"^\| `rrr_pin\.(\w+)` \|([^|]*)\|", README, re.M)
    assert {layer for layer, _ in rows} == {"validation", "outputs", "model", "robust", "control",
                                            "sim", "deploy", "campaign", "report", "cli"}
    for layer, modules in rows:
        # a module as `name`, a subpackage as `name/` with its modules after it
        listed = set(re.findall(r"`(\w+)/?`", modules))
        folder = ROOT / "src" / "rrr_pin" / layer
        present = set()
        if folder.is_dir():
            present = {p.stem for p in folder.glob("*.py") if not p.stem.startswith("_")}
            for sub in folder.iterdir():
                if (sub / "__init__.py").is_file():
                    present |= {sub.name} | {p.stem for p in sub.glob("*.py")
                                             if not p.stem.startswith("_")}
        assert listed == present, f"README's layer table, rrr_pin.{layer}"
