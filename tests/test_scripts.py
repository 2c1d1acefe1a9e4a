"""Every script runs with small settings, so none rots."""

import runpy
import sys
from pathlib import Path

import pytest

SCRIPTS = Path(__file__).resolve().parents[1] / "scripts"

RUNS = [
    ("simulate_nominal.py", ["--duration", "0.2", "--out", "{tmp}/nominal.png"]),
    ("uncertain_study.py", ["--samples", "2", "--duration", "0.2", "--jobs", "1",
                            "--out", "{tmp}/uncertain.png"]),
]


def test_bench_runs_and_reports_its_keys(monkeypatch, capsys):
    # Only that it runs and prints the documented keys: speed is never asserted in tests.
    import json

    argv = [str(SCRIPTS / "bench.py"), "--json", "--duration", "0.05", "--repeat", "1",
            "--calls", "10", "--mc-samples", "2"]
    monkeypatch.setattr(sys, "argv", argv)
    runpy.run_path(str(SCRIPTS / "bench.py"), run_name="__main__")
    data = json.loads(capsys.readouterr().out)
    assert set(data["rollout_ms"]) == {"python", "compiled", "compiled_prepared"}
    assert data["floor_ms"] > 0
    assert set(data["montecarlo_rollouts_per_s"]) == {"1", "2"}


@pytest.mark.parametrize("script,args", RUNS, ids=[r[0] for r in RUNS])
def test_script_runs(script, args, tmp_path, monkeypatch, capsys):
    argv = [str(SCRIPTS / script)] + [a.format(tmp=tmp_path) for a in args]
    monkeypatch.setattr(sys, "argv", argv)
    runpy.run_path(str(SCRIPTS / script), run_name="__main__")
    assert "wrote" in capsys.readouterr().out
    assert list(tmp_path.glob("*.png"))
