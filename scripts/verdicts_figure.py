"""A design's error ratio per plant, on the ideal loop and behind its delay and actuator.
======================================================================================

Reproduces the figure of ``docs/guide/verdicts.md``: the tracking-error ratio (FL alone at
lam = 100 rad/s over the law, RMS, simulated) of each plant of the design's set, once on the
ideal sampled loop and once behind the delay and the actuator the design was asked to run
behind, with the requirement's target. Without ``--design``, the paper's design
(``rrr_pin.design()``, lam = 45 rad/s).

    python scripts/verdicts_figure.py --design tuned/design.json --out verdicts.png
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from rrr_pin.campaign.design_file import load_design, tuned_law  # noqa: E402
from rrr_pin.campaign.tuning import _context, _Eval  # noqa: E402
from rrr_pin.control.references import default_reference  # noqa: E402
from rrr_pin.model.dynamics import load_robot  # noqa: E402
from rrr_pin.model.uncertainty import Tolerances  # noqa: E402


def main() -> None:
    """Simulate the set twice and draw the ratios."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--design", default=None, help="a design.json (default: the paper's)")
    p.add_argument("--robot", default="rrr")
    p.add_argument("--plants", type=int, default=20, help="uncertain plants (seeds [0, k])")
    p.add_argument("--delay", type=float, default=0.002, help="delay [s]")
    p.add_argument("--actuator", type=float, default=300.0, help="actuator bandwidth [rad/s]")
    p.add_argument("--target", type=float, default=10.0, help="required error ratio [-]")
    p.add_argument("--duration", type=float, default=4.0, help="simulated time [s]")
    p.add_argument("--out", default="verdicts.png")
    a = p.parse_args()
    robot = load_robot(a.robot)
    if a.design:
        law = tuned_law(load_design(a.design), robot)
        from pathlib import Path

        lam, K, label = law.lam, law.K, f"design {Path(a.design).parent.name}/design.json"
    else:
        import rrr_pin

        lam, K, label = 45.0, rrr_pin.design().K_reduced, "the paper's design"
    plants = [robot] + [robot.perturbed(np.random.default_rng([0, k]), Tolerances())[0]
                        for k in range(a.plants)]
    ratios = {}
    for name, fx in (("ideal loop", {}),
                     (f"behind {1e3 * a.delay:g} ms + {a.actuator:g} rad/s",
                      {"delay": a.delay, "actuator": a.actuator})):
        ctx = _context(robot, plants, default_reference(robot), 1000.0, {}, a.duration, fx)
        sim = ctx.simulated(_Eval(ctx, lam, K))
        each = np.array(sim["error_ratio_per_plant"], dtype=float)
        each[list(sim["diverged"])] = 0.0
        ratios[name] = (each, sim["error_ratio"])
    fig, ax = plt.subplots(figsize=(7, 3.6))
    x = np.arange(len(plants))
    for (name, (each, pooled)), marker in zip(ratios.items(), "ox", strict=True):
        ax.plot(x, each, marker, label=f"{name}: pooled {pooled:.3g}")
    ax.axhline(a.target, color="k", lw=0.8, ls="--", label=f"required {a.target:g}")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_xlabel("plant of the set (0: nominal)")
    ax.set_ylabel("RMS error ratio FL / law [-]")
    ax.set_title(f"{robot.name}, {label}", fontsize=9)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(a.out, dpi=120)
    for name, (_, pooled) in ratios.items():
        print(f"{name}: pooled error ratio {pooled:.4g}")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
