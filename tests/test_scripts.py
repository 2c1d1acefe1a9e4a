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


@pytest.mark.parametrize("script,args", RUNS, ids=[r[0] for r in RUNS])
def test_script_runs(script, args, tmp_path, monkeypatch, capsys):
    argv = [str(SCRIPTS / script)] + [a.format(tmp=tmp_path) for a in args]
    monkeypatch.setattr(sys, "argv", argv)
    runpy.run_path(str(SCRIPTS / script), run_name="__main__")
    assert "wrote" in capsys.readouterr().out
    assert list(tmp_path.glob("*.png"))
