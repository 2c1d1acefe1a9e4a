"""Designs and campaigns at scale (issue 48): bounded memory, refusals named up front.

The tuner evaluates its plants block by block (:func:`rrr_pin.tune`'s ``block``): the result
must not depend on the block size. Each margin estimate is the worst over the plants, so the
worst of the blocks' worsts is the same number; only the pooled error ratio sums its energies
in another order, equal to rounding (a relative 1e-12 covers the few ulps of a sum of four
terms, propagated through a Nelder-Mead search that compares objectives). Memory itself is
measured in ``scripts/bench.py``, never asserted here.
"""

from __future__ import annotations

import pytest
from numpy.testing import assert_allclose

from rrr_pin.campaign.executors import check_jobs, max_jobs
from rrr_pin.campaign.requirements import DelayMargin, DiskMargin, ErrorRatio
from rrr_pin.campaign.tuning import tune
from rrr_pin.control.structures import Gain
from rrr_pin.validation import FieldError


def _tune(rrr, block):
    return tune(rrr, Gain(lam=None), [DelayMargin(0.004), DiskMargin(0.5), ErrorRatio(5.0)],
                plants=3, starts=1, maxfev=16, verify=False, block=block)


def test_tuned_design_is_the_same_for_any_block(rrr):
    whole = _tune(rrr, None)
    for block in (1, 4):      # 4 plants (with the nominal): blocks of 1, and one of 4
        res = _tune(rrr, block)
        # 1e-12: the error ratio's energies summed block by block (see the module docstring)
        assert_allclose(res.values, whole.values, rtol=1e-12)
        assert_allclose(res.objective, whole.objective, rtol=1e-12)
        assert_allclose([r["achieved"] for r in res.table],
                        [r["achieved"] for r in whole.table], rtol=1e-12)
        assert res.starts[0]["evaluations"] == whole.starts[0]["evaluations"]


@pytest.mark.parametrize("kw, field", [({"block": 0}, "block"),
                                       ({"starts": 10 ** 9}, "starts"),
                                       ({"plants": 10 ** 9}, "plants")],
                         ids=["block-0", "starts-1e9", "plants-1e9"])
def test_search_that_cannot_finish_is_refused_up_front(rrr, kw, field):
    args = {"plants": 1, "starts": 1, "block": 32, **kw}
    with pytest.raises(FieldError, match=field) as info:
        tune(rrr, Gain(lam=None), [DelayMargin(0.004)], verify=False, **args)
    assert info.value.field == field


def test_jobs_bounded_by_the_machine():
    assert check_jobs(max_jobs()) == max_jobs()
    with pytest.raises(ValueError, match="this machine runs at most"):
        check_jobs(max_jobs() + 1)


def test_sample_indices_stream_lazily():
    from rrr_pin.campaign.montecarlo import _blocks

    # 10^12 samples: the first chunks come at once (a list of every index would not fit)
    blocks = _blocks(iter(range(10 ** 12)), 10 ** 12, 32, 2, 1)
    assert next(blocks) == tuple(range(32))
    assert next(blocks) == tuple(range(32, 64))


def test_campaign_too_large_for_the_disk_is_refused(tmp_path):
    from rrr_pin.campaign.store import DiskTooSmall, check_room, row_bytes

    with pytest.raises(DiskTooSmall, match=r"need about .* TB on disk"):
        check_room(tmp_path / "new", 10 ** 12, row_bytes(2, 3))
    check_room(tmp_path, 10, row_bytes(2, 3))   # 10 rows fit


def test_campaign_tables_same_for_any_flush_and_without_figures(rrr, tmp_path):
    import rrr_pin.campaign.montecarlo as mc
    from rrr_pin.campaign.runner import RunSettings, make_laws
    from rrr_pin.control.references import study_reference
    from rrr_pin.report.campaign import write_campaign

    laws = make_laws(["fl", "pd"], rrr)
    settings = mc.CampaignSettings(samples=3, run=RunSettings(duration=0.1, rate=1000.0))
    reference = study_reference(rrr, settings.run.duration)
    tables = {}
    for chunk, figures in ((1, True), (100, False)):   # 4 flushes and a figure, 1 and none
        out = tmp_path / f"c{chunk}"
        with mc.open_store(out, rrr, laws, settings, reference) as store:
            campaign = mc.run_campaign(rrr, laws, settings, jobs=1, chunk=chunk, store=store)
            summary = write_campaign(campaign, out, store=store, figures=figures)
        assert (out / "montecarlo.png").exists() == figures
        assert not any(p.endswith(".png") for p in summary["written"]) or figures
        tables[chunk] = {name: (out / name).read_text()
                         for name in ("campaign.csv", "samples.jsonl", "summary.json")}
    assert tables[1] == tables[100]
