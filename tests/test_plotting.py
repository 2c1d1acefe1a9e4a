"""rrr_pin.report.plotting: figures drawn into given axes, returned open, legends off the data.

Each figure is checked against numbers the test computes itself from the objects plotted
(medians with numpy, RMS errors from the trajectories, the margins of the design).
"""

from html.parser import HTMLParser

import matplotlib.pyplot as plt
import numpy as np
import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg
from numpy.testing import assert_allclose

from rrr_pin.campaign.montecarlo import CampaignSettings, run_campaign
from rrr_pin.campaign.runner import RunSettings, make_laws
from rrr_pin.campaign.study import StudyConfig, run_study
from rrr_pin.report import plotting
from rrr_pin.sim.trajectory import Trajectory


@pytest.fixture(scope="module")
def study(rrr):
    laws = make_laws("fl,hinf", rrr)
    return run_study(rrr, laws, config=StudyConfig(run=RunSettings(duration=0.3), samples=3,
                                                    seed=1, jobs=1))


@pytest.fixture(scope="module")
def campaign(rrr):
    laws = make_laws("fl,hinf", rrr)
    return run_campaign(rrr, laws, CampaignSettings(samples=12, seed=2, run=RunSettings(
        duration=0.3, rate=1000.0)), jobs=1)


# A stress search's result, written by hand (the search itself takes a minute): sizes in s.
STRESS = {"effect": "delay", "unit": "s", "what": "actuator transport delay tau_d",
          "budget_rad": 0.05, "rows": [
              {"label": "FL alone", "unit": "s", "predicted": 0.00597, "simulated": 0.00604,
               "guaranteed": 0.00106,
               "samples": [{"size": 0.002, "rms_error": 7e-4, "status": "passed"},
                           {"size": 0.004, "rms_error": 7e-4, "status": "passed"},
                           {"size": 0.006, "rms_error": 6e-3, "status": "passed"},
                           {"size": 0.0065, "rms_error": None, "status": "diverged"}]},
              {"label": "PD", "unit": "s", "predicted": None, "simulated": 0.0131,
               "guaranteed": None,
               "samples": [{"size": 0.01, "rms_error": 0.011, "status": "passed"},
                           {"size": 0.0132, "rms_error": 0.07, "status": "over budget"}]}]}


def _figures(paper, study, campaign):
    return {
        "fig2": lambda ax: plotting.plot_barriers(paper, ax=ax),
        "fig3": lambda ax: plotting.plot_shaped_plant(paper, ax=ax),
        "fig4a": lambda ax: plotting.plot_robust_stability(paper, ax=ax),
        "fig4b": lambda ax: plotting.plot_robust_performance(paper, ax=ax),
        "certificates": lambda ax: plotting.plot_certificates([0.1, 0.3, 0.5], 0.4,
                                                              [True, True, False], ax=ax),
        "stress": lambda ax: plotting.plot_stress(STRESS, ax=ax),
    }


SINGLE = ["fig2", "fig3", "fig4a", "fig4b", "certificates", "stress"]


@pytest.mark.parametrize("name", SINGLE)
def test_single_axes_figure_draws_into_the_given_axes_and_leaves_it_open(name, paper, study,
                                                                         campaign):
    fig, ax = plt.subplots()
    try:
        out = _figures(paper, study, campaign)[name](ax)
        assert out is fig
        assert plt.fignum_exists(fig.number)  # not closed
        assert ax.lines or ax.collections
    finally:
        plt.close(fig)


@pytest.mark.parametrize("grid", ["array", "figure"])
def test_study_and_campaign_figures_take_axes_or_a_figure(grid, study, campaign):
    fig = plt.figure()
    try:
        axes = fig.subplots(2, 2) if grid == "array" else fig
        assert plotting.plot_study_uncertain(study, axes=axes) is fig
        assert len(fig.axes) == 4 and plt.fignum_exists(fig.number)
        fig.clear()
        axes = fig.subplots(1, 2) if grid == "array" else fig
        assert plotting.plot_campaign(campaign, axes=axes) is fig
        assert len(fig.axes) == 2
    finally:
        plt.close(fig)


def test_wrong_number_of_axes_is_refused(study):
    fig, axes = plt.subplots(1, 3)
    try:
        with pytest.raises(ValueError, match="axes: expected 2 x 2 axes, got 3"):
            plotting.plot_study_nominal(study, axes=axes)
    finally:
        plt.close(fig)


def _all_figures(paper, study, campaign):
    figs = {name: make(None) for name, make in _figures(paper, study, campaign).items()}
    figs["fig5"] = plotting.plot_study_nominal(study)
    figs["fig6"] = plotting.plot_study_uncertain(study)
    figs["montecarlo"] = plotting.plot_campaign(campaign)
    return figs


def test_no_legend_covers_any_axes(paper, study, campaign):
    # A legend outside every axes cannot cover data drawn inside one.
    for name, fig in _all_figures(paper, study, campaign).items():
        FigureCanvasAgg(fig).draw()
        legends = [ax.get_legend() for ax in fig.axes if ax.get_legend()] + fig.legends
        assert legends, name
        for legend in legends:
            box = legend.get_window_extent().padded(-1.0)  # shared edges do not count
            for ax in fig.axes:
                assert not box.overlaps(ax.get_window_extent()), (name, ax.get_title())


def test_module_figures_hold_no_pyplot_state(paper):
    before = plt.get_fignums()
    plotting.plot_barriers(paper)
    assert plt.get_fignums() == before


def test_stress_marks_simulated_and_predicted_limits_in_ms():
    ax = plotting.plot_stress(STRESS).axes[0]
    assert ax.get_xlabel() == "actuator transport delay tau_d [ms]"
    vlines = {line.get_label(): line.get_xdata()[0] for line in ax.lines
              if line.get_label().startswith(("FL alone:", "PD:")) and "limit" in
              line.get_label()}
    # seconds to milliseconds: 1e3, tolerance of a float product
    assert_allclose(vlines["FL alone: simulated limit 6.04 ms"], 6.04, rtol=1e-12)
    assert_allclose(vlines["FL alone: predicted limit 5.97 ms"], 5.97, rtol=1e-12)
    assert_allclose(vlines["PD: simulated limit 13.1 ms"], 13.1, rtol=1e-12)
    assert not any(k.startswith("PD: predicted") for k in vlines)  # no prediction, no line


def test_campaign_medians_visible_and_axes_fit_the_data(campaign):
    fig = plotting.plot_campaign(campaign)
    ax1, ax2 = fig.axes
    rows, joints = campaign.rows, campaign.joint_names
    # Box plots: one black median line per law and joint, at numpy's median.
    medians = sorted(float(np.mean(line.get_ydata())) for line in ax2.lines
                     if line.get_color() == "k" and line.get_linewidth() == 2.0
                     and len(line.get_ydata()) == 2)
    expected = sorted(float(np.median([r[f"{k}_rms_error_{j}"] for r in rows]))
                      for k in campaign.names for j in joints)
    assert_allclose(medians, expected, rtol=1e-12)  # same numbers, only a float mean of two
    values = np.array([r[f"{k}_rms_error_{j}"] for r in rows for k in campaign.names
                       for j in joints])
    lo, hi = ax2.get_ylim()
    # The log axis is the data's range plus 0.08 decade each side (_log_limits).
    assert_allclose(np.log10([lo, hi]), np.log10([values.min(), values.max()]) + [-0.08, 0.08],
                    atol=1e-9)
    ratios = np.array([r["error_ratio_hinf"] for r in rows])
    lo, hi = ax1.get_xlim()
    # The ratios' range plus 0.03 decade each side (before: down to ratio 1, 60 % empty).
    assert_allclose(np.log10([lo, hi]), np.log10([ratios.min(), ratios.max()]) + [-0.03, 0.03],
                    atol=1e-9)
    assert any(line.get_linestyle() == "--" and
               np.isclose(line.get_xdata()[0], np.median(ratios), rtol=1e-12)
               for line in ax1.lines)


def test_uncertain_figure_outlines_the_nominal_runs(study):
    fig = plotting.plot_study_uncertain(study)
    ax = fig.axes[0]  # torques of the first law
    outlined = [line for line in ax.lines if line.get_path_effects()]
    tau = study.nominal[study.names[0]].tau
    assert len(outlined) == tau.shape[1]
    for j, line in enumerate(outlined):
        assert_allclose(line.get_ydata(), tau[:, j], rtol=0, atol=0)  # the same array


def test_fig4a_labels_say_whose_margin(paper):
    ax = plotting.plot_robust_stability(paper).axes[0]
    labels = [line.get_label() for line in ax.lines]
    rs = paper.robust_stability
    assert (f"smallest margin, RSB minus the controlled plant's CLS: {rs.margin_db:.2f} dB at "
            f"{rs.worst_frequency:.4g} rad/s") in labels


# --- _repr_html_ ---------------------------------------------------------------------------

class _Checker(HTMLParser):
    """Collect the text and check that every opened tag is closed, in order."""

    VOID = {"br", "img", "meta"}

    def __init__(self):
        super().__init__()
        self.stack, self.text = [], []

    def handle_starttag(self, tag, attrs):
        if tag not in self.VOID:
            self.stack.append(tag)

    def handle_endtag(self, tag):
        assert self.stack and self.stack.pop() == tag, tag

    def handle_data(self, data):
        self.text.append(data)


def _parse(page: str) -> str:
    checker = _Checker()
    checker.feed(page)
    checker.close()
    assert not checker.stack
    return " ".join(checker.text)


def test_trajectory_repr_html_has_its_numbers():
    t = np.linspace(0.0, 2.0, 201)
    r = np.zeros((t.size, 2))
    q = r - np.array([0.1, 0.0]) - np.array([0.0, 0.2]) * np.sin(2 * np.pi * t)[:, None]
    traj = Trajectory(t=t, q=q, qd=np.zeros_like(q), r=r, tau=np.full_like(q, -3.5),
                      controller="hinf", plant="rrr", info={"engine": "python",
                                                             "rate_hz": 1000.0})
    text = _parse(traj._repr_html_())
    # RMS of a constant 0.1 is 0.1; of 0.2 sin over 2 whole periods sampled at both ends,
    # 0.2 sqrt(1/2 * 200/201) (the 201 samples hold 200 intervals and the sin is 0 at both).
    rms2 = 0.2 * np.sqrt(0.5 * 200 / 201)
    for s in ("rrr", "hinf", "duration [s]", "2 (201 samples)", "1000 (sampled law)",
              "python", "RMS error per joint [rad]", f"0.1, {rms2:.4g}", "peak |torque| [N m]",
              "3.5", "ran"):
        assert s in text, s


def test_study_and_campaign_repr_html_have_their_numbers(study, campaign):
    text = _parse(study._repr_html_())
    for name in study.names:
        e = study.nominal[name].error
        assert f"{np.sqrt(np.mean(e ** 2)):.4g}" in text
        runs = [s["trajectories"][name].error for s in study.samples]
        assert f"{np.mean([np.sqrt(np.mean(x ** 2)) for x in runs]):.4g}" in text
    assert "nominal RMS error [rad]" in text and "ran on 3 of 3 uncertain plants" in text
    text = _parse(campaign._repr_html_())
    for name in campaign.names:
        v = [r[f"{name}_rms_error"] for r in campaign.rows]
        assert f"{np.median(v):.4g}" in text and f"{np.max(v):.4g}" in text
    assert "median RMS error [rad]" in text and "ran on 12 of 12 plants" in text


# --- report.html of a study and of a campaign: headings, captions, units -------------------

class _Tables(HTMLParser):
    """Headings in order, figure captions, and each table's rows of cells."""

    def __init__(self):
        super().__init__()
        self.headings, self.captions, self.tables = [], [], []
        self._open, self._text, self._row, self._cells = [], None, None, []

    def handle_starttag(self, tag, attrs):
        if tag in ("h1", "h2", "h3", "h4", "h5", "h6", "figcaption", "td", "th"):
            self._text = []
        if tag == "table":
            self._open.append([])
        if tag == "tr":
            self._cells.append([])

    def handle_endtag(self, tag):
        text = "".join(self._text or []).strip()
        if tag in ("h1", "h2", "h3", "h4", "h5", "h6"):
            self.headings.append((int(tag[1]), text))
        elif tag == "figcaption":
            self.captions.append(text)
        elif tag in ("td", "th") and self._cells:
            self._cells[-1].append(text)
        elif tag == "tr" and self._open:
            self._open[-1].append(self._cells.pop())
        elif tag == "table":
            self.tables.append(self._open.pop())

    def handle_data(self, data):
        if self._text is not None:
            self._text.append(data)


def _check_report(page: str, n_figures: int):
    p = _Tables()
    p.feed(page)
    levels = [lvl for lvl, _ in p.headings]
    assert levels[0] == 1 and levels.count(1) == 1
    assert all(b <= a + 1 for a, b in zip(levels, levels[1:], strict=False)), p.headings
    figures = [c for c in p.captions
               if c.startswith(("Fig.", "Left:", "Frozen", "The design's loop", "Task "))]
    assert len(figures) == n_figures
    assert not [c for c in p.captions if c.endswith(".png")]
    number = r"^-?\d[\d.e+-]*$"
    import re
    for rows in p.tables:
        header = rows[0]
        if "unit" in header:  # key-value tables: every number has a unit
            u = header.index("unit")
            for row in rows[1:]:
                if re.match(number, row[1]) or row[1].startswith("["):
                    assert row[u], row
            continue
        for c, name in enumerate(header[1:], start=1):  # else: a number's column or row
            for row in rows[1:]:                          # label says its unit
                if len(row) > c and re.match(number, row[c]):
                    assert "[" in name or "[" in row[0], (name, row)


@pytest.mark.parametrize("reproduced", ["rrr", "fivebar"], indirect=True)
def test_study_report_has_one_hierarchy_captions_and_units(reproduced):
    # The shared `rrr-pin reproduce` run's page: every figure it wrote, captioned.
    page = (reproduced.out / "report.html").read_text()
    _check_report(page, len(list(reproduced.out.glob("*.png"))))
    assert "10.50 dB at 207.7 rad/s" in page and "RSB minus the controlled plant" in page


def test_campaign_report_has_one_hierarchy_captions_and_units(tmp_path, campaign):
    from rrr_pin.report.campaign import write_campaign, write_campaign_report

    summary = write_campaign(campaign, tmp_path)
    page = write_campaign_report(campaign, summary, tmp_path).read_text()
    _check_report(page, 1)


def test_study_figures_share_the_error_scale_and_name_the_plant_effects(study):
    # Issue 31: panels (c) and (d) of Fig. 6 on one y-scale, so the controllers' error sizes
    # compare; the titles name the effects the plants carry, not only the tolerances.
    from dataclasses import replace

    from rrr_pin.control.effects import PlantEffects

    for fig in (plotting.plot_study_uncertain(study), plotting.plot_study_nominal(study)):
        cols = len(study.names)
        errors = fig.axes[cols:2 * cols]
        assert len({ax.get_ylim() for ax in errors}) == 1
        assert "with" not in fig._suptitle.get_text()  # no effects in this study
    fx = PlantEffects(viscous=0.5, delay=0.002)
    carried = replace(study, config=replace(study.config, run=replace(study.config.run,
                                                                      effects=fx, rate=1000.0)))
    title = plotting.plot_study_uncertain(carried)._suptitle.get_text()
    assert "20% on masses and moments, 5% on lengths; with delay 2 ms, viscous friction " \
           "0.5 N m s" in title
    nominal = plotting.plot_study_nominal(carried)._suptitle.get_text()
    assert "exact model" not in nominal and "viscous friction 0.5 N m s" in nominal
    assert plotting.plant_effects_phrase(PlantEffects()) == ""
