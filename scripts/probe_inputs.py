"""Hostile inputs through the command line and the public API, each outcome classified.
====================================================================================

Reproduces the hostile-input probe of issue 31: every family of bad inputs the issue lists
(identification logs and options, an identified uncertainty set, export, closed chains and MJCF
files, loop-shaping weights, trajectory files, option values, robot names, badly scaled ``mu``)
is run in a subprocess with a time limit, and each outcome is one of

* ``clear``: refused with exit status 2 (an API case: a ``ValueError`` or ``OSError``), one
  line naming the option or file, no traceback;
* ``correct``: accepted, and the result checked right;
* ``silent``: accepted when it should have been refused, or accepted and wrong;
* ``hang``: still running at the time limit;
* ``unclear``: a traceback, another exit status, or a message that does not name the input.

Writes ``--out`` (JSON: every case with its command, outcome and message) and prints the
counts per family. Inputs are generated in ``--workdir`` (a temporary folder by default).

Usage::

    python scripts/probe_inputs.py --out probe.json
    python scripts/probe_inputs.py --cases window-0,confidence-alone --out /tmp/p.json
"""

import argparse
import json
import re
import subprocess
import sys
import tempfile
import textwrap
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

OUTCOMES = ("clear", "correct", "silent", "hang", "unclear")


@dataclass(frozen=True)
class Case:
    """One hostile input: CLI arguments (``argv``) or a Python snippet (``code``)."""

    family: str
    name: str
    argv: tuple = ()
    code: str = ""
    refuse: bool = True
    names: tuple = ()        # each must appear in the message of a clear refusal
    check: str = ""          # accepted cases: a snippet printing "OK" when the result is right
    shows: str = ""          # accepted CLI cases: a regular expression the output must match
    needs: tuple = field(default=())


def _cli(*args) -> tuple:
    return ("rrr-pin",) + args


def cases() -> list[Case]:
    """Return the probe's cases, by family (the issue's lists)."""
    ex = ("identify", "--design-excitation")
    mc = ("montecarlo", "--samples", "1", "--duration", "0.1", "--no-progress", "--jobs", "1")
    out = [
        # identification: logs and options
        Case("identify", "degrees", _cli("identify", "--data", "{w}/deg.csv", "--out", "{o}"),
             names=("q_joint", "degrees"), needs=("log",)),
        Case("identify", "bom", _cli("identify", "--data", "{w}/bom.csv", "--out", "{o}"),
             refuse=False, check="import json; r = json.load(open('{o}/identification.json'));"
             " print('OK' if r['base_count'] == 15 else 'BAD')", needs=("log",)),
        Case("identify", "window-0", _cli("identify", "--data", "{w}/ok.csv", "--window", "0",
                                          "--out", "{o}"), names=("--window",), needs=("log",)),
        Case("identify", "window-nan", _cli("identify", "--data", "{w}/ok.csv", "--window",
                                            "nan", "--out", "{o}"), names=("--window",),
             needs=("log",)),
        Case("identify", "harmonics-0", _cli(*ex, "--harmonics", "0", "--out", "{o}"),
             names=("--harmonics",)),
        Case("identify", "harmonics-2000", _cli(*ex, "--harmonics", "2000", "--out", "{o}"),
             names=("--harmonics",)),
        Case("identify", "frequency-1e-7", _cli(*ex, "--frequency", "1e-7", "--out", "{o}"),
             names=("--frequency",)),
        Case("identify", "csv-rate-1e9", _cli(*ex, "--csv-rate", "1e9", "--out", "{o}"),
             names=("--csv-rate",)),
        Case("identify", "csv-rate-0", _cli(*ex, "--csv-rate", "0", "--out", "{o}"),
             names=("--csv-rate",)),
        # an identified uncertainty set
        *[Case("uncertainty", f"missing-{key}", _cli(*mc, "--uncertainty", f"{{w}}/no_{key}.json",
                                                     "--out", "{o}"),
               names=(f"no_{key}.json", key), needs=("records",))
          for key in ("joints", "kinematics", "base", "cov")],
        *[Case("uncertainty", f"cov-{kind}", _cli(*mc, "--uncertainty", f"{{w}}/cov_{kind}.json",
                                                  "--out", "{o}"),
               names=(f"cov_{kind}.json", "cov"), needs=("records",))
          for kind in ("not-pd", "nan", "shape")],
        Case("uncertainty", "base-count", _cli(*mc, "--uncertainty", "{w}/base14.json", "--out",
                                               "{o}"), names=("base14.json", "base parameters"),
             needs=("records",)),
        Case("uncertainty", "confidence-alone", _cli(*mc, "--confidence", "7", "--out", "{o}"),
             names=("--confidence", "--uncertainty")),
        Case("uncertainty", "confidence-chain", _cli(*mc, "--robot", "fivebar", "--confidence",
                                                     "0.9", "--out", "{o}"),
             names=("--confidence",)),
        # export
        Case("export", "fl-rate-1", _cli("export", "--law", "fl", "--rate", "1", "--out", "{o}"),
             names=("--rate", "Hz")),
        Case("export", "rate-nan", _cli("export", "--law", "pd", "--rate", "nan", "--out",
                                        "{o}"), names=("--rate",)),
        Case("export", "continuous-joint", _cli("export", "--robot", "{w}/continuous.urdf",
                                                "--law", "fl", "--rate", "1000", "--out", "{o}"),
             refuse=False, check="import json; r = json.load(open('{o}/controller.json'));"
             " print('OK' if r['nq'] == 3 else 'BAD')", needs=("urdf",)),
        # closed chains and MJCF files
        *[Case("mjcf", f"mjcf-{kind}", _cli("margins", "--robot", f"{{w}}/{kind}.xml"),
               names=(f"{kind}.xml",), needs=("mjcf",))
          for kind in ("negative-mass", "nan-mass", "malformed", "empty", "rootless",
                       "keyframe")],
        Case("mjcf", "home-outside-limits", _cli("margins", "--home", "9,0,0"),
             names=("--home",)),
        # the "unreachable" 5-bar configuration: the loop closes there, on the other
        # assembly mode (the check closes it and measures the tips' gap)
        Case("mjcf", "fivebar-3-minus-3", _cli("margins", "--robot", "fivebar", "--home",
                                               "3,-3"), refuse=False, check=textwrap.dedent("""
            import numpy as np
            from rrr_pin import load_robot
            chain = load_robot("fivebar")
            gap = float(np.max(np.abs(chain.residual(chain.close([3.0, -3.0])))))
            print("OK" if gap < 1e-9 else f"BAD gap {gap:.3g} m")""")),
        Case("mjcf", "close-3-minus-3", code=textwrap.dedent("""
            import numpy as np
            from rrr_pin import load_robot
            chain = load_robot("fivebar")
            q = chain.close([3.0, -3.0])
            gap = float(np.max(np.abs(chain.residual(q))))  # the tips' distance [m]
            print("OK" if gap < 1e-9 else f"BAD gap {gap:.3g} m")"""), refuse=False),
        # loop-shaping weights
        Case("weights", "2dof-w2-strictly-proper", code=textwrap.dedent("""
            import control
            from rrr_pin.robust.loopshaping import fl_plant, lag_weight
            from rrr_pin.robust.ncf import ncfsyn_2dof
            s = control.tf("s")
            ncfsyn_2dof(fl_plant(45.0, 1), 90.0**2 / (s + 90.0)**2, 1.1, lag_weight(),
                        1 / (s + 1))"""), names=("W2",)),
        Case("weights", "loopsyn-rank-one-target", code=textwrap.dedent("""
            import control
            from rrr_pin.robust.loopshaping import fl_plant, loopsyn
            Gd = control.tf([[[8.0], [8.0]], [[8.0], [8.0]]], [[[1.0, 0.0]] * 2] * 2)
            loopsyn(fl_plant(45.0, 2), Gd)"""), names=("Gd",)),
        Case("weights", "loopsyn-singular-d-target", code=textwrap.dedent("""
            import control, numpy as np
            from rrr_pin.robust.loopshaping import fl_plant, loopsyn
            G = fl_plant(45.0, 2)
            r = loopsyn(G, control.ss(np.zeros((2, 2)), 8 * np.eye(2), np.eye(2), np.ones((2, 2))))
            CL = control.feedback(G * r.K, np.eye(2))
            ok = np.isfinite(r.gamma) and np.all(CL.poles().real < 0)
            print("OK" if ok else "BAD")"""), refuse=False),
        # trajectory files
        *[Case("trajectory", f"load-{kind}", code=f"from rrr_pin import Trajectory\n"
               f"Trajectory.load('{{w}}/{kind}')", names=(kind,), needs=("trajectories",))
          for kind in ("backwards.csv", "swapped.npz", "binary.npz", "truncated.npz",
                       "folder.npz", "truncated.mat")],
        Case("trajectory", "mat-round-trip", code=textwrap.dedent("""
            import numpy as np
            from rrr_pin import Trajectory
            a, b = Trajectory.load("{w}/ok.npz"), None
            a.save("{w}/again.mat")
            b = Trajectory.load("{w}/again.mat")
            print("OK" if all(np.array_equal(getattr(a, k), getattr(b, k))
                              for k in ("t", "q", "qd", "r", "tau")) else "BAD")"""),
             refuse=False, needs=("trajectories",)),
        # option values
        Case("options", "rate-nan", _cli(*mc, "--rate", "nan", "--out", "{o}"),
             names=("--rate",)),
        Case("options", "duration-0", _cli("montecarlo", "--samples", "1", "--duration", "0",
                                           "--out", "{o}"), names=("--duration",)),
        Case("options", "torque-limit-negative", _cli("reproduce", "--rate", "1000",
                                                      "--torque-limit", "-5%", "--out", "{o}"),
             names=("--torque-limit",)),
        Case("options", "home-negative", _cli("margins", "--home", "-9,0,0"),
             names=("--home",)),
        # robot names
        # the built-in arm, 7 joints, not the folder; the Panda's fingers locked, 7 joints
        Case("names", "folder-named-xarm7", _cli("margins", "--robot", "xarm7",
                                                 "--controllers", "fl"),
             refuse=False, shows=r"^xarm7 at q = \[(-?[\d.]+, ){6}-?[\d.]+\] rad",
             needs=("xarm7-folder",)),
        Case("names", "panda-by-name", _cli("margins", "--robot", "panda", "--controllers",
                                            "fl"), refuse=False,
             shows=r"^panda at q = \[(-?[\d.]+, ){6}-?[\d.]+\] rad"),
        # issue 50: silent and unclear cases the probe found
        *[Case("issue50", f"require-{name}", _cli("design", "--robot", "rrr", "--require", text,
                                                 "--samples", "1", "--starts", "1",
                                                 "--no-simulate", "--out", "{o}"),
               names=("--require", word))
          for name, text, word in (("delay-1e9", "delay_margin=1e9", "delay_margin"),
                                   ("delay-negative", "actuator_bandwidth=300,delay=-1",
                                    "delay"),
                                   ("delay-nan", "actuator_bandwidth=300,delay=nan", "delay"))],
        Case("issue50", "tune-lam-with-lam-0", _cli("design", "--robot", "rrr", "--tune-lam",
                                                    "--lam", "0", "--out", "{o}"),
             names=("--lam", "--tune-lam")),
        Case("issue50", "per-joint-lam-600", _cli("design", "--robot", "rrr", "--per-joint-lam",
                                                  "--lam", "600", "--out", "{o}"),
             names=("--lam", "500")),
        Case("issue50", "design-json-without-K", _cli(*mc, "--controllers", "fl,tuned",
                                                      "--design", "{w}/noK.json", "--out",
                                                      "{o}"),
             names=("noK.json", "K"), needs=("designs",)),
        Case("issue50", "threads-compiled", _cli(*mc, "--threads", "2", "--engine", "compiled",
                                                 "--out", "{o}"), names=("--threads", "--jobs")),
        Case("issue50", "friction-urdf-without-friction",
             _cli(*mc, "--rate", "1000", "--friction", "urdf", "--out", "{o}"),
             names=("friction 'urdf'", "no joint friction")),
        *[Case("issue50", f"reference-option-{opt[2:]}",
               _cli("reproduce", "--robot", robot, opt, value, "--samples", "1",
                    "--duration", "0.1", "--no-progress", "--out", "{o}"),
               names=(opt, "--reference"))
          for robot, opt, value in (("fivebar", "--radius", "0.1"), ("rrr", "--move-time", "1"),
                                    ("rrr", "--csv", "x.csv"))],
        Case("issue50", "mat-with-inf", code=textwrap.dedent("""
            import numpy as np
            from rrr_pin import Trajectory
            a = Trajectory.load("{w}/ok.npz")
            a.q = a.q.copy(); a.q[3, 1] = np.inf
            a.save("{w}/inf.mat")
            Trajectory.load("{w}/inf.mat")"""), names=("inf.mat", "q[3, 1]"),
             needs=("trajectories",)),
        Case("issue50", "threerrr-impossible-q0",
             _cli("reproduce", "--robot", "threerrr", "--q0", "5,5,5", "--samples", "1",
                  "--duration", "0.1", "--no-progress", "--out", "{o}"), names=("--q0",)),
        Case("issue50", "margins-lower-upper", _cli("margins", "--controllers", "hinf"),
             refuse=False, shows=r"gain margins: x0\.046 to inf"),
        # mu on a badly scaled matrix (SLICOT AB13MD's published bound 41.7475, scaled 1e6)
        Case("mu", "ab13md-scaled-1e6", code=textwrap.dedent("""
            import numpy as np
            from rrr_pin.robust.mu import mussv
            Z = np.array([[-1+6j, 2-3j, 3+8j, 3+8j, -5-9j, -6+2j],
                          [4+2j, -2+5j, -6-7j, -4+11j, 8-7j, 12-1j],
                          [5-4j, -4-8j, 1-3j, -6+14j, 2-5j, 4+16j]] * 2)
            d = np.array([1, 1e6, 1e-6, 1e-6, 1e3, 1e-3])
            up, _ = mussv(d[:, None] * Z / d[None, :], [("real", 1), ("real", 1),
                          ("complex", 2), ("complex", 1), ("complex", 1)], lower=False)
            print("OK" if abs(up[0] / 41.74753408 - 1) < 0.01 else f"BAD {up[0]:.4g}")"""),
             refuse=False),
    ]
    return out


# --- inputs -----------------------------------------------------------------------------------

def _log(w: Path) -> None:
    from rrr_pin import load_robot
    from rrr_pin.model import identification as idn
    from rrr_pin.model.excitation import FourierTrajectory

    robot = load_robot("rrr")
    rng = np.random.default_rng(0)
    traj = FourierTrajectory(0.2, 0.4 * rng.standard_normal((3, 5)),
                             0.4 * rng.standard_normal((3, 5)), np.zeros(3), 2)
    t = np.arange(0.0, 10.0, 0.02)
    q, qd, qdd = traj.sample(t)
    tau = np.array([robot.inverse_dynamics(*x) for x in zip(q, qd, qdd, strict=True)])
    tau += 0.05 * rng.standard_normal(tau.shape)
    for name, qq, bom in (("ok", q, ""), ("bom", q, "\ufeff"), ("deg", np.degrees(q), "")):
        data = idn.Measurements(t, qq, qd, qdd, tau, tuple(robot.joint_names))
        idn.write_measurements(w / f"{name}.csv", data)
        if bom:
            path = w / f"{name}.csv"
            path.write_text(bom + path.read_text(encoding="utf-8"), encoding="utf-8")


def _records(w: Path) -> None:
    from rrr_pin.cli import main

    _prepare(w, "log")
    if main(["identify", "--data", str(w / "ok.csv"), "--held-out", "0", "--out",
             str(w / "identified")]) != 0:
        raise RuntimeError("the probe's identification of its own log failed")
    record = json.loads((w / "identified" / "identification.json").read_text())

    def write(name, edit):
        r = json.loads(json.dumps(record))
        edit(r)
        (w / name).write_text(json.dumps(r))

    for key in ("joints", "kinematics", "base", "cov"):
        write(f"no_{key}.json", lambda r, k=key: r.pop(k))
    write("cov_not-pd.json", lambda r: r.update(cov=(-np.array(r["cov"])).tolist()))
    write("cov_nan.json", lambda r: r["cov"][0].__setitem__(0, float("nan")))
    write("cov_shape.json", lambda r: r.update(cov=[row[:-1] for row in r["cov"][:-1]]))

    def fewer(r, k=14):
        for key in ("estimate", "std", "base_consistent"):
            r[key] = r[key][:k]
        r["cov"] = [row[:k] for row in r["cov"][:k]]
        if "cov_all" in r:  # base parameters first, then friction (and armature) columns
            n = len(r["cov_all"])
            keep = [i for i in range(n) if i < k or i >= r["base_count"]]
            r["cov_all"] = [[r["cov_all"][i][j] for j in keep] for i in keep]
        r["base_count"] = k
        for key in ("names", "expressions", "independent", "K"):
            r["base"][key] = r["base"][key][:k]

    write("base14.json", fewer)


def _urdf(w: Path) -> None:
    text = (Path(__file__).resolve().parents[1] / "urdf" / "rrr.urdf").read_text()
    (w / "continuous.urdf").write_text(text.replace('type="revolute"', 'type="continuous"', 1))


def _mjcf(w: Path) -> None:
    import re

    text = (Path(__file__).resolve().parents[1] / "mjcf" / "fivebar.xml").read_text()
    first_mass = re.search(r'mass="([^"]+)"', text)
    (w / "negative-mass.xml").write_text(text.replace(first_mass.group(0), 'mass="-1.0"', 1))
    (w / "nan-mass.xml").write_text(text.replace(first_mass.group(0), 'mass="nan"', 1))
    (w / "malformed.xml").write_text(text[:len(text) // 2])
    (w / "empty.xml").write_text("")
    (w / "rootless.xml").write_text('<?xml version="1.0"?>\n')
    key = re.search(r'qpos="([^"]+)"', text)
    (w / "keyframe.xml").write_text(text.replace(key.group(0), 'qpos="0 0"', 1))


def _trajectories(w: Path) -> None:
    from rrr_pin import Trajectory

    rng = np.random.default_rng(1)
    N = 20
    traj = Trajectory(t=np.linspace(0.0, 1.0, N), q=rng.normal(size=(N, 3)),
                      qd=rng.normal(size=(N, 3)), r=rng.normal(size=(N, 3)),
                      tau=rng.normal(size=(N, 3)), controller="fl", plant="rrr",
                      joint_names=["joint1", "joint2", "joint3"])
    traj.save(w / "ok.npz")
    back = Trajectory(**{k: getattr(traj, k)[::-1] for k in ("t", "q", "qd", "r", "tau")},
                      joint_names=traj.joint_names)
    back.save(w / "backwards.csv")
    order = np.arange(N)
    order[[4, 5]] = [5, 4]
    Trajectory(**{k: getattr(traj, k)[order] for k in ("t", "q", "qd", "r", "tau")},
               joint_names=traj.joint_names).save(w / "swapped.npz")
    (w / "binary.npz").write_bytes(bytes(range(256)) * 4)
    whole = (w / "ok.npz").read_bytes()
    (w / "truncated.npz").write_bytes(whole[:len(whole) // 2])
    traj.save(w / "ok.mat")
    whole = (w / "ok.mat").read_bytes()
    (w / "truncated.mat").write_bytes(whole[:len(whole) // 2])
    (w / "folder.npz").mkdir(exist_ok=True)


def _designs(w: Path) -> None:
    from rrr_pin.campaign.design_file import DESIGN_FORMAT

    (w / "noK.json").write_text(json.dumps({"format": DESIGN_FORMAT, "robot": "rrr",
                                            "joints": ["joint1", "joint2", "joint3"],
                                            "lam_rad_s": 45.0}))


def _xarm7_folder(w: Path) -> None:
    (w / "xarm7").mkdir(exist_ok=True)
    (w / "xarm7" / "notes.txt").write_text("a folder named like a robot")


_PREPARE = {"log": _log, "records": _records, "urdf": _urdf, "mjcf": _mjcf,
            "trajectories": _trajectories, "xarm7-folder": _xarm7_folder,
            "designs": _designs}
_DONE: set = set()


def _prepare(w: Path, need: str) -> None:
    if need not in _DONE:
        _PREPARE[need](w)
        _DONE.add(need)


# --- running and classifying ------------------------------------------------------------------

_WRAP = """
import sys
try:
{body}
except (ValueError, OSError) as exc:
    print(f"{{type(exc).__name__}}: {{exc}}", file=sys.stderr)
    sys.exit(2)
"""


def _fill(text: str, w: Path, o: Path) -> str:
    """``text`` with ``{w}`` (the work folder) and ``{o}`` (the case's output) filled in."""
    return text.replace("{w}", str(w)).replace("{o}", str(o))


def _command(case: Case, w: Path, o: Path) -> list[str]:
    if case.argv:
        args = [_fill(a, w, o) for a in case.argv[1:]]
        return [sys.executable, "-m", "rrr_pin.cli", *args]
    body = textwrap.indent(_fill(case.code, w, o).strip(), "    ")
    return [sys.executable, "-c", _WRAP.format(body=body)]


def classify(case: Case, rc, out: str, err: str, checked: str) -> tuple[str, str]:
    """Return ``(outcome, why)`` of one run (``rc`` None: timed out)."""
    if rc is None:
        return "hang", "timed out"
    lines = [line for line in err.splitlines() if line.strip()]
    message = next((line for line in reversed(lines) if "error" in line.lower()
                    or line.split(":")[0].endswith(("Error", "Exception"))), lines[-1]
                   if lines else "")
    if "Traceback" in err:
        return "unclear", "traceback"
    if case.refuse:
        if rc == 0:
            return "silent", "accepted"
        if rc != 2:
            return "unclear", f"exit status {rc}"
        missing = [n for n in case.names if n.lower() not in message.lower()]
        if missing:
            return "unclear", f"the message does not name {missing}"
        return "clear", message
    if rc != 0:
        return "unclear", f"refused a valid input (exit {rc}): {message}"
    if case.shows:
        if re.search(case.shows, out, re.M):
            return "correct", f"output matches {case.shows!r}"
        return "silent", f"accepted, but the output does not match {case.shows!r}"
    if checked.strip().endswith("OK") or out.strip().endswith("OK"):
        return "correct", "checked"
    return "silent", f"accepted but wrong: {(checked or out).strip()[-200:]}"


def run_case(case: Case, w: Path, timeout: float) -> dict:
    """Run one case in a subprocess; return its record."""
    for need in case.needs:
        _prepare(w, need)
    o = w / "out" / case.name
    cmd = _command(case, w, o)
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=w)
        rc, out, err = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired:
        rc, out, err = None, "", ""
    checked = ""
    if rc == 0 and case.check:
        checked = subprocess.run([sys.executable, "-c", _fill(case.check, w, o)],
                                 capture_output=True, text=True, cwd=w).stdout
    outcome, why = classify(case, rc, out, err, checked)
    shown = cmd[2:] if case.argv else ["python", "-c", case.code.strip()]
    return {"family": case.family, "case": case.name, "command": shown, "exit": rc,
            "outcome": outcome, "why": why}


def main() -> None:
    """Parse the options, run the cases, write the JSON and print the table."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", default=None, metavar="NAME,NAME",
                        help="run only these cases (default: all; --list shows them)")
    parser.add_argument("--timeout", type=float, default=120.0, metavar="S",
                        help="time limit of one case [s] (120)")
    parser.add_argument("--workdir", default=None, metavar="DIR",
                        help="folder for the generated inputs (default: a temporary one)")
    parser.add_argument("--list", action="store_true", help="list the cases and stop")
    parser.add_argument("--out", default="probe.json", help="JSON report (probe.json)")
    args = parser.parse_args()
    todo = cases()
    if args.list:
        for c in todo:
            print(f"{c.family:12s} {c.name}")
        return
    if args.cases:
        wanted = [s.strip() for s in args.cases.split(",")]
        unknown = sorted(set(wanted) - {c.name for c in todo})
        if unknown:
            parser.error(f"--cases: unknown {unknown} (see --list)")
        todo = [c for c in todo if c.name in wanted]
    if not args.timeout > 0:
        parser.error(f"--timeout must be > 0 s, got {args.timeout}")
    with tempfile.TemporaryDirectory() as tmp:
        w = Path(args.workdir or tmp).resolve()
        w.mkdir(parents=True, exist_ok=True)
        records = []
        for case in todo:
            rec = run_case(case, w, args.timeout)
            records.append(rec)
            print(f"{rec['family']:12s} {rec['case']:28s} {rec['outcome']:8s} {rec['why']}",
                  flush=True)
    families = sorted({r["family"] for r in records}, key=[c.family for c in cases()].index)
    table = {f: {o: sum(r["family"] == f and r["outcome"] == o for r in records)
                 for o in OUTCOMES} for f in families}
    table["all"] = {o: sum(r["outcome"] == o for r in records) for o in OUTCOMES}
    Path(args.out).write_text(json.dumps({"table": table, "cases": records}, indent=1))
    print(f"\n{'family':12s} " + " ".join(f"{o:>8s}" for o in OUTCOMES))
    for f, row in table.items():
        print(f"{f:12s} " + " ".join(f"{row[o]:8d}" for o in OUTCOMES))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
