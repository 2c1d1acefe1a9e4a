"""CampaignStore: refusals before any work, append/resume, torn lines, byte-identical tables."""

import csv
import hashlib
import io
import json
import os

import numpy as np
import pytest

from rrr_pin.campaign.store import (
    MANIFEST,
    PARTS,
    CampaignStore,
    ChecksumMismatch,
    OutputNotEmpty,
    SettingsMismatch,
    StoreCorrupt,
)
from rrr_pin.outputs import OutputNotWritable

SETTINGS = {"seed": 7, "samples": 40, "reference": {"amp": [1.0, 0.5], "freq_hz": 0.2},
            "rate_hz": 1000.0, "engine": "python"}
OUTPUTS = ("campaign.csv", "summary.json")


def toy_row(seed: int, k: int) -> dict:
    """A campaign-like row for sample ``k``: seeded floats, a tuple, nested params, NaN-free.

    Every 7th sample "diverges" and carries no metrics, as in a real campaign.
    """
    rng = np.random.default_rng([seed, k])
    row = {"index": k, "seed": (seed, k), "status": "ok",
           "parameters": {"mass": rng.uniform(0.5, 2.0, 3).tolist(), "note": f"s{k}"}}
    if k % 7 == 3:
        row["status"] = "diverged at t = 0.1 s: joint 'joint2' blew up"
        return row
    row["fl_rms_error"] = float(rng.lognormal(-5, 1))
    row["hinf_rms_error"] = float(rng.lognormal(-6, 1))
    return row


def write_tables(store: CampaignStore) -> None:
    """The caller's final tables, built from ``store.rows()`` only (CSV and a summary)."""
    rows = store.rows()
    buf = io.StringIO(newline="")
    writer = csv.DictWriter(buf, fieldnames=["index", "seed", "status", "fl_rms_error",
                                             "hinf_rms_error"], extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({**row, "seed": row["seed"][0]})
    store.write_text("campaign.csv", buf.getvalue())
    ok = [r for r in rows if r["status"] == "ok"]
    summary = {"samples": len(rows), "ok": len(ok),
               "median_fl": float(np.median([r["fl_rms_error"] for r in ok])),
               "sum_mass": float(np.sum([r["parameters"]["mass"] for r in rows]))}
    store.write_text("summary.json", json.dumps(summary, indent=1) + "\n")


def chunks(indices, size):
    indices = list(indices)
    return [indices[i:i + size] for i in range(0, len(indices), size)]


def straight_run(out, samples=40, seed=7):
    with CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False,
                            outputs=OUTPUTS) as store:
        for chunk in chunks(range(samples), 5):
            store.append([toy_row(seed, k) for k in chunk])
        write_tables(store)
        return list(store.written)


# --- refusals before any work ---------------------------------------------------------------

def test_out_that_is_a_file_is_refused(tmp_path):
    f = tmp_path / "results"
    f.write_text("not a directory")
    with pytest.raises(OutputNotWritable, match="results.*is an existing file"):
        CampaignStore.open(f, settings=SETTINGS, resume=False, overwrite=False)
    with pytest.raises(OutputNotWritable, match="cannot create output directory.*sub"):
        CampaignStore.open(f / "sub", settings=SETTINGS, resume=False, overwrite=False)
    assert f.read_text() == "not a directory"


def test_unwritable_out_is_refused(tmp_path):
    # /proc refuses new entries even to root, so this holds whoever runs the tests.
    with pytest.raises(OutputNotWritable, match="/proc/rrr-pin-test"):
        CampaignStore.open("/proc/rrr-pin-test", settings=SETTINGS, resume=False,
                           overwrite=False)
    if os.geteuid() != 0:  # root ignores directory permissions
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            with pytest.raises(OutputNotWritable, match="ro.*not writable"):
                CampaignStore.open(ro, settings=SETTINGS, resume=False, overwrite=False)
        finally:
            ro.chmod(0o700)


def test_non_empty_out_is_refused_without_resume_or_overwrite(tmp_path):
    out = tmp_path / "mc"
    straight_run(out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    with pytest.raises(OutputNotEmpty, match="not empty.*--resume.*--overwrite"):
        CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before  # nothing touched
    with pytest.raises(ValueError, match="exclusive"):
        CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=True)


def test_resume_of_a_folder_that_holds_no_campaign_is_refused(tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    with pytest.raises(OutputNotEmpty, match="holds no campaign"):
        CampaignStore.open(tmp_path, settings=SETTINGS, resume=True, overwrite=False)


def test_resume_with_other_settings_names_the_keys(tmp_path):
    out = tmp_path / "mc"
    straight_run(out)
    changed = {**SETTINGS, "seed": 8, "reference": {"amp": [1.0, 0.6], "freq_hz": 0.2},
               "extra": 1}
    with pytest.raises(SettingsMismatch,
                       match=r"in extra, reference\.amp, seed: extra \(recorded missing, given 1\)"
                       r".*seed \(recorded 7, given 8\)") as info:
        CampaignStore.open(out, settings=changed, resume=True, overwrite=False)
    assert info.value.keys == ["extra", "reference.amp", "seed"]


def test_bad_rows_are_refused(tmp_path):
    with CampaignStore.open(tmp_path / "mc", settings=SETTINGS, resume=False,
                            overwrite=False) as store:
        store.append([toy_row(7, 0)])
        with pytest.raises(ValueError, match="index 0 is already recorded"):
            store.append([toy_row(7, 0)])
        with pytest.raises(TypeError, match=r"row\['index'\] must be an int"):
            store.append([{"index": "1"}])
        with pytest.raises(TypeError, match="row 2 is not JSON-able"):
            store.append([{"index": 2, "x": np.int64(3)}])
        assert store.done() == {0}
        assert len(store.parts_path.read_bytes().splitlines()) == 1


def test_a_second_writer_is_refused(tmp_path):
    out = tmp_path / "mc"
    with CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False):
        with pytest.raises(StoreCorrupt, match="in use by another running campaign"):
            CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False)


# --- append, resume, overwrite --------------------------------------------------------------

def test_rows_are_on_disk_after_each_append(tmp_path):
    out = tmp_path / "mc"
    store = CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False)
    store.append([toy_row(7, k) for k in (4, 2)])
    # another reader sees them at once, without close()
    lines = (out / PARTS).read_text().splitlines()
    assert [json.loads(s)["index"] for s in lines] == [4, 2]
    store.append([toy_row(7, 0)])
    assert [r["index"] for r in store.rows()] == [0, 2, 4]
    assert store.rows()[1]["seed"] == [7, 2]  # tuples come back as lists (JSON)
    store.close()
    assert json.loads((out / MANIFEST).read_text())["settings"] == SETTINGS


def test_interrupted_then_resumed_tables_are_byte_identical(tmp_path):
    ref = tmp_path / "straight"
    straight_run(ref)

    out = tmp_path / "interrupted"
    store = CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False,
                               outputs=OUTPUTS)
    order = np.random.default_rng(1).permutation(40)  # workers finish in any order
    for chunk in chunks(order[:23], 4):
        store.append([toy_row(7, int(k)) for k in chunk])
    store.close()
    # a process killed in mid-write leaves a torn last line
    torn = json.dumps(toy_row(7, int(order[23])))[:37]
    with open(out / PARTS, "ab") as fh:
        fh.write(torn.encode())

    with CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False,
                            outputs=OUTPUTS) as store:
        assert store.done() == {int(k) for k in order[:23]}
        assert store.resumed == 23
        # the torn line is gone from the file, which ends with a newline again
        assert (out / PARTS).read_bytes().endswith(b"}\n")
        missing = [k for k in range(40) if k not in store.done()]
        for chunk in chunks(missing, 6):
            store.append([toy_row(7, k) for k in chunk])
        write_tables(store)
        assert [p.name for p in store.written] == list(OUTPUTS)
    for name in OUTPUTS:
        assert (out / name).read_bytes() == (ref / name).read_bytes(), name
    rows = [json.loads(s) for s in (ref / PARTS).read_text().splitlines()]
    assert sorted(r["index"] for r in rows) == list(range(40))


def test_a_damaged_last_complete_line_is_dropped_but_not_a_middle_one(tmp_path):
    out = tmp_path / "mc"
    with CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False) as s:
        s.append([toy_row(7, k) for k in range(3)])
    good = (out / PARTS).read_bytes()
    (out / PARTS).write_bytes(good + b"\x00\x00\x00\n")  # power loss: zeros
    with CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False) as s:
        assert s.done() == {0, 1, 2}
    assert (out / PARTS).read_bytes() == good
    lines = good.splitlines(keepends=True)
    (out / PARTS).write_bytes(lines[0] + b"{garbage\n" + lines[2])
    with pytest.raises(StoreCorrupt, match=r"parts.jsonl.* line 2 is damaged"):
        CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False)


def test_resume_of_a_finished_run_rewrites_the_same_tables(tmp_path):
    out = tmp_path / "mc"
    straight_run(out)
    before = {n: (out / n).read_bytes() for n in OUTPUTS}
    with CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False,
                            outputs=OUTPUTS) as store:
        assert store.done() == set(range(40))
        assert not any((out / n).exists() for n in OUTPUTS)  # stale outputs removed first
        write_tables(store)
    assert {n: (out / n).read_bytes() for n in OUTPUTS} == before


def test_overwrite_removes_the_previous_outputs_and_reports_only_its_own(tmp_path):
    out = tmp_path / "mc"
    straight_run(out)
    (out / "montecarlo.png").write_bytes(b"stale figure from an older version")
    (out / "notes.txt").write_text("the user's own file")
    store = CampaignStore.open(out, settings={**SETTINGS, "seed": 9}, resume=False,
                               overwrite=True, outputs=OUTPUTS + ("montecarlo.png",))
    assert store.done() == set() and store.rows() == []
    assert not (out / "campaign.csv").exists() and not (out / "montecarlo.png").exists()
    assert (out / "notes.txt").read_text() == "the user's own file"  # unknown: left alone
    store.append([toy_row(9, 0)])
    store.write_text("summary.json", "{}\n")
    assert store.written == [out / "summary.json"]
    store.close()
    manifest = json.loads((out / MANIFEST).read_text())
    assert manifest["outputs"] == ["summary.json"] and manifest["settings"]["seed"] == 9


def test_wrote_checks_the_file_exists(tmp_path):
    with CampaignStore.open(tmp_path / "mc", settings=SETTINGS, resume=False,
                            overwrite=False) as store:
        with pytest.raises(FileNotFoundError, match="fig.png"):
            store.wrote("fig.png")
        with pytest.raises(ValueError, match="inside"):
            store.write_text("../escape.txt", "x")
        (store.out / "fig.png").write_bytes(b"png")
        assert store.wrote("fig.png") == store.out / "fig.png"
        assert store.written == [store.out / "fig.png"]


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_signal_during_the_write_is_held_until_the_rows_are_counted(tmp_path, monkeypatch, sig):
    # the signal lands inside fsync (where a real one most often does): the rows reach the file
    # and the store counts them, and only then does the interrupt surface
    import signal

    from rrr_pin.campaign.executors import interrupt_on_signals

    real_fsync = os.fsync

    def fsync_hit_by_signal(fd):
        os.kill(os.getpid(), getattr(signal, sig))
        real_fsync(fd)

    with CampaignStore.open(tmp_path / "o", settings=SETTINGS, resume=False,
                            overwrite=False) as store:
        store.append([toy_row(7, 0), toy_row(7, 1)])
        monkeypatch.setattr(os, "fsync", fsync_hit_by_signal)
        with pytest.raises(KeyboardInterrupt, match=f"received {sig}"), interrupt_on_signals():
            store.append([toy_row(7, 2), toy_row(7, 3)])
        monkeypatch.setattr(os, "fsync", real_fsync)
        assert store.done() == {0, 1, 2, 3}
        assert [r["index"] for r in store.rows()] == [0, 1, 2, 3]


# --- row checksums --------------------------------------------------------------------------

def test_each_line_carries_the_documented_checksum(tmp_path):
    # Recomputed here from the layout in the module docstring (hashlib on the JSON texts), not
    # through the store: sha256(sha256(settings, sorted keys) + "\n" + row, sorted, compact).
    out = tmp_path / "mc"
    straight_run(out, samples=6)
    digest = hashlib.sha256(json.dumps(SETTINGS, sort_keys=True).encode()).hexdigest()
    assert json.loads((out / MANIFEST).read_text())["settings_sha256"] == digest
    for line in (out / PARTS).read_text().splitlines():
        row = json.loads(line)
        assert list(row)[-1] == "_sha256"
        recorded = row.pop("_sha256")
        text = json.dumps(row, sort_keys=True, separators=(",", ":"))
        assert recorded == hashlib.sha256(f"{digest}\n{text}".encode()).hexdigest()
        assert row == json.loads(json.dumps(toy_row(7, row["index"])))


def _edit_line(path, n, change):
    """Apply ``change(row) -> row`` to line ``n`` (from 1) of a JSONL file, keeping the rest."""
    lines = path.read_text().splitlines()
    lines[n - 1] = json.dumps(change(json.loads(lines[n - 1])))
    path.write_text("\n".join(lines) + "\n")


def _other_campaigns_line(tmp_path, n):
    """Line ``n`` of a campaign with another seed in its settings (a valid row there)."""
    other = tmp_path / "other"
    with CampaignStore.open(other, settings={**SETTINGS, "seed": 8}, resume=False,
                            overwrite=False) as store:
        store.append([toy_row(7, k) for k in range(40)])
    return json.loads((other / PARTS).read_text().splitlines()[n - 1])


@pytest.mark.parametrize("line,edit", [
    (5, lambda row, _: {**row, "fl_rms_error": row["fl_rms_error"] * 2}),
    (40, lambda row, _: {**row, "status": "ok" if row["status"] != "ok" else "diverged"}),
    (12, lambda row, _: {k: v for k, v in row.items() if k != "_sha256"}),
    (7, lambda row, tmp: _other_campaigns_line(tmp, 7)),
], ids=["value-changed", "last-line", "checksum-removed", "row-from-other-settings"])
def test_an_edited_row_is_refused_on_resume_naming_the_line(tmp_path, line, edit):
    out = tmp_path / "mc"
    straight_run(out)
    _edit_line(out / PARTS, line, lambda row: edit(row, tmp_path))
    before = (out / PARTS).read_bytes()
    with pytest.raises(ChecksumMismatch,
                       match=rf"parts.jsonl' line {line} \(sample \d+\) (does not match its "
                             r"checksum|has no checksum).*--overwrite") as info:
        CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False,
                           outputs=OUTPUTS)
    assert info.value.line == line and info.value.path == out / PARTS
    assert (out / PARTS).read_bytes() == before  # not truncated as a torn line


def test_a_row_edited_during_the_run_is_refused_when_the_tables_are_built(tmp_path):
    out = tmp_path / "mc"
    with CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False) as store:
        store.append([toy_row(7, k) for k in range(3)])
        _edit_line(out / PARTS, 2, lambda row: {**row, "parameters": {"mass": [1, 1, 1]}})
        with pytest.raises(ChecksumMismatch, match=r"line 2 \(sample 1\) does not match"):
            store.rows()


def test_the_checksum_key_is_reserved(tmp_path):
    with CampaignStore.open(tmp_path / "mc", settings=SETTINGS, resume=False,
                            overwrite=False) as store:
        with pytest.raises(ValueError, match="'_sha256' is reserved"):
            store.append([{**toy_row(7, 0), "_sha256": "0" * 64}])
        assert store.done() == set()


def test_a_store_of_version_1_without_checksums_is_refused_on_resume(tmp_path):
    # Written as rrr-pin 0.1.0 did before checksums: manifest version 1, bare JSON rows.
    out = tmp_path / "mc"
    out.mkdir()
    (out / MANIFEST).write_text(json.dumps({"format": "rrr-pin-campaign", "version": 1,
                                            "settings": SETTINGS, "outputs": []}))
    (out / PARTS).write_text("".join(json.dumps(toy_row(7, k)) + "\n" for k in range(3)))
    with pytest.raises(StoreCorrupt, match=r"store version 1.*cannot be verified.*--overwrite"):
        CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False)
    with CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=True) as store:
        assert store.done() == set()  # overwrite starts it afresh


def test_resume_is_logged_with_the_rows_found(tmp_path, caplog):
    import logging

    out = tmp_path / "mc"
    with CampaignStore.open(out, settings=SETTINGS, resume=False, overwrite=False) as store:
        store.append([toy_row(7, k) for k in (0, 3, 5)])
    with caplog.at_level(logging.INFO, logger="rrr_pin.campaign.store"):
        with CampaignStore.open(out, settings=SETTINGS, resume=True, overwrite=False) as store:
            found = len(store.done())
    assert found == 3
    assert [r.getMessage() for r in caplog.records] == [
        f"store {out}: resuming, {found} samples already on disk"]
