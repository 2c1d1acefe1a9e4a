"""Shared fixtures: the models and designs of every test file, and the end-to-end CLI runs.

Models and designs are session-scoped (built once per pytest-xdist worker). **Never mutate
them**: a test that changes a model (its inertias, gravity, locks) loads its own with
:func:`rrr_pin.load_robot`. A session-scoped :class:`~rrr_pin.model.closed_chain.ClosedChain`
carries the Newton seed of its loop closure from one call to the next: every ``simulate`` run
resets it (``Plant.reset``), a test that evaluates the model face at its own states seeds it
there first (``chain.reset(q)``), and after every test each shared chain is re-seeded at home
(``_home_seeds``), so no test depends on where another left it.

* ``rrr`` (the paper's arm), ``ur5``, ``fivebar``, ``delta``, ``threerrr``: the plants;
* ``plant``: one of them by name, for a test parametrized over plant kinds::

      @pytest.mark.parametrize("plant", ["rrr", "fivebar"], indirect=True)
      def test_something(plant): ...

* ``paper``: the paper's design (:func:`rrr_pin.design`, 3 joints); ``design_for(n)``: the
  same design for ``n`` joints (cached), e.g. a certificate on the 5-bar's 2 joints;
* ``reproduced``, ``montecarlo_run``, ``stress_run``: one ``rrr-pin reproduce``,
  ``montecarlo`` and ``stress`` run per plant kind (default ``"rrr"``; parametrize them
  indirectly like ``plant``), for the tests that only read their outputs;
* ``without_figures``: a test's own ``rrr-pin reproduce`` writes results.json without drawing
  its figures and report.html (for a claim about what reached the study).

A shared run is made once per test session, also under pytest-xdist (``-n 2``): the first
worker that needs it runs it in the session's common temporary folder, under a file lock, and
the others read what it wrote (its folder, exit status and output).
"""

import contextlib
import functools
import io
import json
import os
from pathlib import Path
from typing import NamedTuple

import matplotlib
import pytest

matplotlib.use("Agg")

# Generated dynamics built at first use (rrr_pin.sim.dyncache) go to the repository's build/
# folder during the tests, never to the user's cache.
os.environ.setdefault("RRR_PIN_CACHE", str(Path(__file__).resolve().parents[1] / "build"
                                           / "test-dyncache"))

# Load the compiled extension once, before any test captures sys.stdout: in an editable
# development install its import may first rebuild it in a subprocess, which needs real file
# descriptors (a regular install has no such step).
import rrr_pin.sim.compiled  # noqa: E402, F401
from rrr_pin import cli, load_robot  # noqa: E402


def _strict_loads(text: str):
    """``json.loads`` refusing NaN and Infinity, which are not JSON (RFC 8259; jq, JS refuse)."""
    def refuse(name):
        raise ValueError(f"not JSON: {name}")
    return json.loads(text, parse_constant=refuse)


@pytest.fixture
def strict_json():
    """The strict JSON parser: every JSON file or stream the tool writes must pass it."""
    return _strict_loads


# --- plants and designs ------------------------------------------------------------------------

@pytest.fixture(scope="session")
def rrr():
    """The paper's RRR arm (Tables 1-2)."""
    return load_robot("rrr")


@pytest.fixture(scope="session")
def ur5():
    """example-robot-data's UR5."""
    return load_robot("ur5")


#: The shared closed chains made so far in this process (re-seeded after every test).
_CHAINS = []


def _chain(name):
    chain = load_robot(name)
    _CHAINS.append(chain)
    return chain


@pytest.fixture(autouse=True)
def _home_seeds():
    """After each test, put every shared closed chain's Newton seed back at home."""
    yield
    for chain in _CHAINS:
        chain.reset()


@pytest.fixture(scope="session")
def fivebar():
    """The built-in planar 5-bar (a closed chain, 2 actuated joints)."""
    return _chain("fivebar")


@pytest.fixture(scope="session")
def delta():
    """The built-in Delta (a closed chain, 3 actuated joints)."""
    return _chain("delta")


@pytest.fixture(scope="session")
def threerrr():
    """The built-in 3-RRR planar parallel manipulator (3 actuated joints)."""
    return _chain("threerrr")


@pytest.fixture(scope="session")
def plant(request):
    """The plant fixture named by an indirect parametrization (``"rrr"``, ``"fivebar"``, ...)."""
    return request.getfixturevalue(request.param)


@pytest.fixture(scope="session")
def design_for():
    """``design_for(n)``: the paper's design (:func:`rrr_pin.design`) for ``n`` joints, cached."""
    from rrr_pin.robust.loopshaping import design

    return functools.cache(lambda n: design(n=n))


@pytest.fixture(scope="session")
def paper(design_for):
    """The paper's design: lam = 45 rad/s, 3 joints (:func:`rrr_pin.design`)."""
    return design_for(3)


@pytest.fixture(scope="session")
def twodof(rrr):
    """The built-in 2-DOF law ``hinf2dof`` on the nominal RRR (its ncfsyn_2dof design, once)."""
    from rrr_pin.control.catalog import make_law

    return make_law("hinf2dof", rrr)


# --- end-to-end CLI runs, shared by the tests that only read their outputs ---------------------

class CliRun(NamedTuple):
    """One ``rrr-pin`` run: its exit status, output folder, what it printed and its arguments.

    ``argv`` is the command line without ``--out`` (a test may rerun it, e.g. to resume).
    """

    code: int
    out: Path
    stdout: str
    stderr: str
    argv: list


def run_cli(argv, out: Path) -> CliRun:
    """``rrr_pin.cli.main(argv + ["--out", out])``, its standard output and error captured."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = cli.main([*argv, "--out", str(out)])
    return CliRun(code, Path(out), stdout.getvalue(), stderr.getvalue(), list(argv))


#: Small settings of the shared runs, the same for every kind of plant: laws sampled at 1 kHz
#: (which the compiled engines run; continuous-time laws on a closed chain take the Python one).
REPRODUCE = ["reproduce", "--samples", "2", "--duration", "0.3", "--rate", "1000", "--jobs", "1",
             "--save-trajectories", "csv", "--no-progress"]
MONTECARLO = ["montecarlo", "--samples", "2", "--duration", "0.05", "--jobs", "1",
              "--controllers", "fl,hinf,pd", "--no-progress"]
STRESS = ["stress", "--effect", "delay", "--controllers", "fl", "--duration", "0.2", "--json",
          "-v"]


@pytest.fixture(scope="session")
def shared_runs(tmp_path_factory):
    """``shared_runs(argv, robot)``: run ``argv --robot robot`` once per session, then reuse it.

    The run goes to ``<session temp>/shared-runs/<command>_<robot>_<hash of argv>/out``; under
    pytest-xdist the session temp is the workers' common parent folder, and a file lock makes
    one worker run it while the others wait, then read its record (``run.json``). A memo rather
    than a parametrized session fixture: pytest keeps one value per fixture, so tests of
    several plant kinds in turn would otherwise redo a run at each change of kind.
    """
    import fcntl
    import hashlib
    import os

    base = tmp_path_factory.getbasetemp()  # a worker's is <session temp>/popen-gw<k>
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "shared-runs"
    root.mkdir(parents=True, exist_ok=True)
    runs = {}

    def get(argv, robot) -> CliRun:
        key = (tuple(argv), robot)
        if key not in runs:
            digest = hashlib.sha256(json.dumps([*argv, robot]).encode()).hexdigest()[:8]
            folder = root / f"{argv[0]}_{robot}_{digest}"
            with open(root / f"{folder.name}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes
                record = folder / "run.json"
                if record.exists():
                    done = json.loads(record.read_text())
                    runs[key] = CliRun(done["code"], folder / "out", done["stdout"],
                                       done["stderr"], done["argv"])
                else:
                    run = run_cli([*argv, "--robot", robot], folder / "out")
                    record.write_text(json.dumps({"code": run.code, "stdout": run.stdout,
                                                  "stderr": run.stderr, "argv": run.argv}))
                    runs[key] = run
        return runs[key]

    return get


@pytest.fixture
def reproduced(request, shared_runs):
    """``rrr-pin reproduce`` (2 uncertain plants, 0.3 s at 1 kHz, trajectories as CSV)."""
    return shared_runs(REPRODUCE, getattr(request, "param", "rrr"))


@pytest.fixture
def montecarlo_run(request, shared_runs):
    """``rrr-pin montecarlo`` (fl, hinf, pd; 2 plants, 50 ms at 1 kHz) of a plant kind."""
    return shared_runs(MONTECARLO, getattr(request, "param", "rrr"))


@pytest.fixture
def stress_run(request, shared_runs):
    """``rrr-pin stress --effect delay --json -v`` of FL alone, of a plant kind (default rrr)."""
    return shared_runs(STRESS, getattr(request, "param", "rrr"))


def _random_model(model, rng):
    """A copy of ``model`` with random physical parameters: placements, inertias, armature."""
    import numpy as np
    import pinocchio as pin

    m = model.copy()
    for i in range(1, m.njoints):
        R = pin.exp3(rng.normal(size=3))
        m.jointPlacements[i] = pin.SE3(R, rng.uniform(-0.5, 0.5, 3))
        # I = tr(S) 1 - S for a random positive definite S: a rigid body's inertia.
        A = rng.normal(size=(3, 3))
        S = 0.05 * (A @ A.T + 0.1 * np.eye(3))
        m.inertias[i] = pin.Inertia(rng.uniform(0.5, 5.0), rng.uniform(-0.2, 0.2, 3),
                                    np.trace(S) * np.eye(3) - S)
    m.armature[:] = rng.uniform(0.0, 0.1, m.nv)
    m.gravity = pin.Motion(np.r_[rng.normal(size=3), 0.0, 0.0, 0.0])
    return m


@pytest.fixture(scope="session")
def generated_matches_pinocchio():
    """``check(name, model, seed, B)``: generated dynamics ``name`` == Pinocchio's, random models.

    B copies of ``model`` with random placements, inertias, armature and gravity, at random
    states: the generated M, nonLinearEffects, G, inverse dynamics (``M a + nle``) and forward
    dynamics (both algorithms of the
    structures compiled in: the chosen one and the other, CRBA + L D L^T and the generated ABA;
    a structure built at first use holds the chosen one) against Pinocchio's CRBA,
    nonLinearEffects, computeGeneralizedGravity and ABA (an independent implementation).
    """
    import numpy as np
    import pinocchio as pin
    from numpy.testing import assert_allclose

    from rrr_pin.sim import dyngen
    from rrr_pin.sim.extension import EXTENSION

    def check(name, model, seed, B):
        rng = np.random.default_rng(seed)
        n = model.nq
        models = [_random_model(model, rng) for _ in range(B)]
        P = np.stack([dyngen.parameters(m) for m in models])
        q, v, tau = (rng.uniform(-3.0, 3.0, (B, n)) for _ in range(3))
        M, nle, g, qdd, qdd_other, inv = EXTENSION.batch_dynamics(name, P, q, v, tau)
        for b, m in enumerate(models):
            d = m.createData()
            Mp = pin.crba(m, d, q[b])
            Mp = np.triu(Mp) + np.triu(Mp, 1).T
            # the inverse dynamics (tau read as an acceleration): M a + nle from Pinocchio's
            # CRBA (armature on its diagonal) and nonLinearEffects, against one generated RNEA
            assert_allclose(inv[b], Mp @ tau[b] + pin.nonLinearEffects(m, d, q[b], v[b]),
                            rtol=0.0, atol=1e-12 * np.abs(Mp @ tau[b]).max())
            # 1e-12 relative (issue 23): both are exact algorithms in double; measured ~1e-15.
            for got, want in ((M[b].reshape(n, n), Mp),
                              (nle[b], pin.nonLinearEffects(m, d, q[b], v[b])),
                              (g[b], pin.computeGeneralizedGravity(m, d, q[b])),
                              (qdd[b], pin.aba(m, d, q[b], v[b], tau[b])),
                              (qdd_other[b], pin.aba(m, d, q[b], v[b], tau[b]))):
                assert_allclose(got, want, rtol=0.0, atol=1e-12 * np.abs(want).max())

    return check


@pytest.fixture
def without_figures(monkeypatch, tmp_path):
    """``rrr-pin reproduce`` draws no figure and writes no report.html in this test.

    For the tests whose claim is in results.json (options reaching the study): the figures and
    the report cost most of a small run's CPU (measured: a process running the three tests of
    tests/test_cli.py that use this, 26.6 s -> 5.3 s of CPU), and the shared runs of
    ``reproduced`` check them.
    """
    import rrr_pin.report.margins as margins
    import rrr_pin.report.plotting as plotting
    import rrr_pin.report.results as results

    monkeypatch.setattr(plotting, "save_design_figures", lambda d, out: [])
    monkeypatch.setattr(plotting, "save_study_figures", lambda result, out, plant=None: [])
    monkeypatch.setattr(margins, "save_margins_figure", lambda *a, **k: tmp_path / "m.png")
    monkeypatch.setattr(results, "write_study_report", lambda *a, **k: tmp_path / "r.html")
