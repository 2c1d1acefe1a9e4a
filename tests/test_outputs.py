"""The output-folder rule (rrr_pin.outputs) and the commands that follow it.

The unit tests build folders by hand; the command-line tests use the smallest runs that reach
the code (``--samples 0``/``1``, 0.2 s of simulated time) or a stand-in for the computation.
"""

from __future__ import annotations

import errno
import json
from pathlib import Path

import pytest

from rrr_pin import cli
from rrr_pin.campaign.store import CampaignStore
from rrr_pin.outputs import (
    MANIFEST,
    OutputDir,
    OutputError,
    OutputInUse,
    OutputNotEmpty,
    OutputNotWritable,
    check_writable,
    recorded_runs,
    writing,
)


def _run(out: Path, tool: str = "reproduce", files=("a.png", "sub/b.urdf"), **kw) -> OutputDir:
    run = OutputDir.claim(out, tool, **kw)
    for name in files:
        (out / name).parent.mkdir(parents=True, exist_ok=True)
        (out / name).write_text(name)
    run.close()
    return run


def _manifest(out: Path, name: str = MANIFEST) -> dict:
    return json.loads((out / name).read_text())


# --- the rule ----------------------------------------------------------------------------------

def test_claim_records_exactly_what_the_run_wrote(tmp_path):
    out = tmp_path / "r"
    run = OutputDir.claim(out, "reproduce", settings={"samples": 1, "path": Path("x")})
    m = _manifest(out)
    assert (m["tool"], m["complete"], m["outputs"]) == ("reproduce", False, [])
    (out / "fig2.png").write_text("x")
    (out / "plants").mkdir()
    (out / "plants" / "rrr_000.urdf").write_text("x")
    assert run.close() == ["fig2.png", "plants/rrr_000.urdf"]
    m = _manifest(out)
    assert m["complete"] and m["outputs"] == ["fig2.png", "plants/rrr_000.urdf"]
    assert m["settings"] == {"samples": 1, "path": "PosixPath('x')"}  # non-JSON: its repr


def test_overwrite_removes_only_the_manifests_files(tmp_path):
    out = tmp_path / "r"
    _run(out, files=("certificates.png", "fig2.png", "plants/rrr_000.urdf"))
    (out / "notes.txt").write_text("mine")  # a file no run wrote
    with pytest.raises(OutputNotEmpty, match=r"'.*r' is not empty: it holds a previous run of "
                       r"`rrr-pin reproduce` \(5 entries: certificates.png, fig2.png, notes.txt"
                       r", \.\.\.\).*pass --overwrite"):
        OutputDir.claim(out, "reproduce")
    run = OutputDir.claim(out, "reproduce", overwrite=True)
    assert run.removed == sorted([MANIFEST, "certificates.png", "fig2.png",
                                  "plants/rrr_000.urdf"])
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", MANIFEST]  # plants/ emptied
    (out / "fig2.png").write_text("new")
    assert run.close() == ["fig2.png"]
    assert _manifest(out)["kept"] == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "mine"


def test_unknown_files_need_overwrite_and_are_kept(tmp_path):
    (tmp_path / "data.csv").write_text("1")
    with pytest.raises(OutputNotEmpty, match="files no rrr-pin run recorded .1 entries: "
                       "data.csv.*--overwrite to write beside them"):
        OutputDir.claim(tmp_path, "design")
    run = OutputDir.claim(tmp_path, "design", overwrite=True)
    (tmp_path / "fig2.png").write_text("x")
    assert run.close() == ["fig2.png"] and (tmp_path / "data.csv").read_text() == "1"


def test_another_tools_run_is_refused_even_with_overwrite(tmp_path):
    _run(tmp_path, "stress", part="delay")
    with pytest.raises(OutputInUse, match=r"holds a run of `rrr-pin stress` .*"
                       r"`rrr-pin reproduce` does not write beside it, even with --overwrite: "
                       r"choose another --out"):
        OutputDir.claim(tmp_path, "reproduce", overwrite=True)
    assert (tmp_path / "a.png").is_file()


def test_a_campaign_folder_is_refused_and_a_campaign_refuses_a_study(tmp_path):
    mc = tmp_path / "mc"
    with CampaignStore.open(mc, settings={"samples": 1}) as store:
        store.write_text("campaign.csv", "index\n0\n")
    assert [r.tool for r in recorded_runs(mc)] == ["montecarlo"]
    with pytest.raises(OutputInUse, match=r"holds a run of `rrr-pin montecarlo` \(campaign.csv"):
        OutputDir.claim(mc, "reproduce", overwrite=True)
    study = tmp_path / "study"
    _run(study)
    with pytest.raises(OutputInUse, match="holds a run of `rrr-pin reproduce`"):
        CampaignStore.open(study, settings={}, overwrite=True)
    assert (study / "a.png").is_file()


def test_parts_of_one_tool_share_a_folder(tmp_path):
    # stress --effect delay and --effect actuator: one manifest each, neither touches the other
    _run(tmp_path, "stress", files=("stress_delay.png",), part="delay")
    _run(tmp_path, "stress", files=("stress_actuator.png",), part="actuator")
    with pytest.raises(OutputNotEmpty, match="previous run.*rrr-pin-run-delay.json"):
        OutputDir.claim(tmp_path, "stress", part="delay")
    run = OutputDir.claim(tmp_path, "stress", part="delay", overwrite=True)
    assert run.removed == sorted(["rrr-pin-run-delay.json", "stress_delay.png"])
    assert (tmp_path / "stress_actuator.png").is_file()


def test_a_nested_run_is_a_separate_run(tmp_path):
    _run(tmp_path / "montecarlo", "stress", part="delay")
    run = OutputDir.claim(tmp_path, "reproduce")  # empty but for a nested run: no --overwrite
    (tmp_path / "x.png").write_text("x")
    assert run.close() == ["x.png"]
    assert (tmp_path / "montecarlo" / "a.png").is_file()


def test_a_run_that_died_is_cleaned_by_the_next_overwrite(tmp_path):
    (tmp_path / "keep.txt").write_text("k")
    OutputDir.claim(tmp_path, "reproduce", overwrite=True)
    (tmp_path / "fig2.png").write_text("x")  # killed before close(): nothing listed
    assert not _manifest(tmp_path)["complete"]
    run = OutputDir.claim(tmp_path, "reproduce", overwrite=True)
    assert run.removed == sorted(["fig2.png", MANIFEST])
    assert (tmp_path / "keep.txt").is_file()


def test_a_run_that_wrote_nothing_leaves_no_trace(tmp_path):
    out = tmp_path / "new"
    OutputDir.claim(out, "reproduce").close()
    assert not out.exists()


@pytest.mark.parametrize("where, message", [
    ("file", r"--out: output directory '.*file' exists and is not a folder .*choose another"),
    ("under-file", r"--out: cannot create output directory '.*file/sub'.*not writable"),
    ("/proc/rrr-pin-x", r"--out: cannot create output directory '/proc/rrr-pin-x'"),
], ids=["file", "under-file", "proc"])
def test_not_writable(tmp_path, where, message):
    (tmp_path / "file").write_text("x")
    out = {"file": tmp_path / "file", "under-file": tmp_path / "file" / "sub"}.get(where, where)
    with pytest.raises(OutputNotWritable, match=message):
        OutputDir.claim(out, "design")
    with pytest.raises(OutputNotWritable, match=message):
        check_writable(out)


def test_a_damaged_manifest_is_refused(tmp_path):
    (tmp_path / MANIFEST).write_text("{not json")
    with pytest.raises(OutputError, match="not a readable rrr-pin manifest"):
        OutputDir.claim(tmp_path, "reproduce", overwrite=True)


def test_writing_names_the_file():
    with pytest.raises(OSError, match="No space") as info:
        with writing("out/fig2.png"):
            raise OSError(errno.ENOSPC, "No space left on device")  # as Pillow's write does
    assert (info.value.errno, info.value.filename) == (errno.ENOSPC, "out/fig2.png")


def test_store_full_disk_keeps_the_previous_table(tmp_path, monkeypatch):
    import rrr_pin.campaign.store as store_module

    with CampaignStore.open(tmp_path, settings={}) as store:
        store.write_text("summary.json", "old")

        def full(fd):
            raise OSError(errno.ENOSPC, "No space left on device")

        monkeypatch.setattr(store_module.os, "fsync", full)
        with pytest.raises(OSError, match="No space") as info:
            store.write_text("summary.json", "new")
    assert info.value.filename == str(tmp_path / "summary.json")
    assert (tmp_path / "summary.json").read_text() == "old"
    assert not list(tmp_path.glob(".*.tmp"))


# --- the commands ------------------------------------------------------------------------------

_FAST = ["--duration", "0.2", "--jobs", "1", "--no-progress", "--controllers", "fl"]


def _fail(*args, **kwargs):
    raise AssertionError("computed before --out was checked")


@pytest.mark.parametrize("where", ["/proc/rrr-pin-x", "file"], ids=["proc", "file"])
def test_design_out_refused_before_the_design(tmp_path, capsys, monkeypatch, where):
    import rrr_pin.robust.loopshaping as loopshaping

    monkeypatch.setattr(loopshaping, "design", _fail)
    (tmp_path / "file").write_text("x")
    out = where if where.startswith("/") else str(tmp_path / where)
    assert cli.main(["design", "--out", out]) == 2
    err = capsys.readouterr().err
    assert "rrr-pin design: error: --out: " in err and out in err and "Traceback" not in err


def test_reproduce_twice_into_one_folder(reproduced, tmp_path, capsys):
    import shutil

    out = tmp_path / "r"
    shutil.copytree(reproduced.out, out)  # a finished run of `rrr-pin reproduce` (shared)
    assert {"certificates.png", "plants", "report.html"} <= {p.name for p in out.iterdir()}
    (out / "notes.txt").write_text("mine")
    capsys.readouterr()
    assert cli.main(["reproduce", "--out", str(out), "--samples", "0", "--no-certify",
                     *_FAST]) == 2
    err = capsys.readouterr().err
    assert "is not empty: it holds a previous run of `rrr-pin reproduce`" in err
    assert "--overwrite" in err and "Traceback" not in err
    assert cli.main(["reproduce", "--out", str(out), "--samples", "0", "--no-certify",
                     "--overwrite", *_FAST]) == 0
    names = {p.name for p in out.iterdir()}
    assert "certificates.png" not in names and not list(out.glob("plants/*.urdf"))
    assert (out / "notes.txt").read_text() == "mine"
    m = _manifest(out)
    assert m["complete"] and "results.json" in m["outputs"] and m["kept"] == ["notes.txt"]
    assert m["settings"]["samples"] == 0
    assert json.loads((out / "results.json").read_text())["config"]["samples"] == 0


def test_reproduce_and_stress_refuse_a_campaign_folder(tmp_path, capsys, monkeypatch):
    import rrr_pin.model.dynamics as dynamics

    monkeypatch.setattr(dynamics, "load_robot", _fail)  # refused before the robot loads
    with CampaignStore.open(tmp_path, settings={}) as store:
        store.write_text("campaign.csv", "index\n")
    for argv in (["reproduce", "--no-progress", "--overwrite"],
                 ["stress", "--effect", "delay", "--overwrite"]):
        assert cli.main(argv + ["--out", str(tmp_path)]) == 2
        err = capsys.readouterr().err
        assert "holds a run of `rrr-pin montecarlo` (campaign.csv" in err
        assert "even with --overwrite" in err and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign.csv", "campaign.json",
                                                          "parts.jsonl"]


def test_stress_refuses_its_previous_run_without_overwrite(tmp_path, capsys, monkeypatch):
    import rrr_pin.model.dynamics as dynamics

    monkeypatch.setattr(dynamics, "load_robot", _fail)
    _run(tmp_path, "stress", files=("stress_delay.png",), part="delay")
    assert cli.main(["stress", "--effect", "delay", "--out", str(tmp_path)]) == 2
    assert "previous run of `rrr-pin stress`" in capsys.readouterr().err


def _full_disk(monkeypatch):
    import matplotlib.figure

    def savefig(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")  # no file name, as Pillow's

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)


def test_reproduce_full_disk(tmp_path, capsys, monkeypatch):
    _full_disk(monkeypatch)
    out = tmp_path / "r"
    assert cli.main(["reproduce", "--out", str(out), "--samples", "0", "--no-certify",
                     *_FAST]) == 2
    err = capsys.readouterr().err
    assert (f"rrr-pin reproduce: error: cannot write {out / 'fig2.png'}: No space left on "
            "device (ENOSPC)") in err and "Traceback" not in err


def test_montecarlo_full_disk_keeps_the_rows(tmp_path, capsys, monkeypatch):
    _full_disk(monkeypatch)
    out = tmp_path / "m"
    argv = ["montecarlo", "--out", str(out), "--samples", "2", *_FAST]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert f"cannot write {out / 'montecarlo.png'}: No space left on device (ENOSPC)" in err
    assert "--resume" in err and "Traceback" not in err
    assert len((out / "parts.jsonl").read_text().splitlines()) == 3  # and the nominal plant
    monkeypatch.undo()
    assert cli.main(argv + ["--resume"]) == 0
    assert "resuming: 3 of 3 plants (with the nominal) already done" in capsys.readouterr().out
    assert (out / "montecarlo.png").is_file()


def test_a_bad_option_under_overwrite_keeps_the_previous_run(tmp_path, capsys):
    # --overwrite removes the previous run only once the options are checked: a mistyped
    # option is refused with the previous results still there.
    _run(tmp_path)
    assert cli.main(["reproduce", "--out", str(tmp_path), "--overwrite", "--samples", "-1"]) == 2
    assert "--samples" in capsys.readouterr().err
    assert (tmp_path / "a.png").read_text() == "a.png"
    assert (tmp_path / "sub" / "b.urdf").exists()


def test_manifest_says_whether_the_command_finished(tmp_path, monkeypatch, capsys):
    # Issue 31: `reproduce --robot xarm7` exited 2 after writing its results, and its manifest
    # said "complete": true with nothing saying the run had failed. `finished` now records it.
    from rrr_pin.cli import main
    from rrr_pin.deploy.writer import Export

    assert main(["export", "--law", "pd", "--rate", "500", "--out", str(tmp_path / "ok")]) == 0
    assert _manifest(tmp_path / "ok")["finished"] is True

    def write_then_fail(self, folder):
        (Path(folder) / "partial.txt").write_text("x")
        raise ValueError("failed after writing")

    monkeypatch.setattr(Export, "write", write_then_fail)
    assert main(["export", "--law", "pd", "--rate", "500", "--out", str(tmp_path / "bad")]) == 2
    assert "failed after writing" in capsys.readouterr().err
    m = _manifest(tmp_path / "bad")
    assert m["complete"] and m["outputs"] == ["partial.txt"] and m["finished"] is False
