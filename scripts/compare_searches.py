"""Fixed-structure tuning: the searches compared at equal evaluations.
===================================================================

The README's two comparisons:

1. The paper's loop-shaping index (NCF gamma of the shaped loop, lam = 45 rad/s, the paper's
   W1) over an order-2 ``K``: bounded Nelder-Mead on a log scale against
   ``rrr_pin.hinfstruct``, from ``K = 1`` and seeded random starts.
2. ``rrr_pin.tune`` on the RRR (``delay_margin=0.006``, ``error_ratio=10``,
   ``actuator_bandwidth=300,delay=0.002``, ``lam`` tuned) with ``search="nelder-mead"`` and
   ``search="minimax"``, the same evaluations per start.

Prints the worst value of each start of each search (lower is better) and draws them,
start by start, in ``--out`` (PNG).
"""

from __future__ import annotations

import argparse

import control
import numpy as np
from scipy.optimize import minimize

from rrr_pin import hinfstruct, load_robot, tune
from rrr_pin.campaign.requirements import make_requirement
from rrr_pin.control.structures import make_structure
from rrr_pin.robust.hinfstruct import TunableFunction, lft_loop, ncf_plant
from rrr_pin.robust.loopshaping import fl_plant, lag_weight


def loop_shaping(starts: int, maxfev: int, seed: int) -> None:
    """Table 1: Nelder-Mead against hinfstruct on the paper's loop-shaping index."""
    st = make_structure("order2")
    K = TunableFunction("K", st.outer_names, tuple(st.outer_initial()), st.K,
                        limits=tuple(st.outer_bounds()))
    P = ncf_plant(fl_plant(45.0, 1), lag_weight())
    b = np.log(np.array(st.outer_bounds()))
    count = [0]

    def gamma(z):
        count[0] += 1
        cl = lft_loop(P, [K], [np.exp(np.clip(z, b[:, 0], b[:, 1]))])
        if np.linalg.eigvals(cl.A).real.max() >= 0:
            return 1e3
        return control.linfnorm(cl)[0]

    rng = np.random.default_rng(seed)
    z0 = np.log(st.outer_initial())
    z0s = [z0] + [np.clip(z0 + rng.standard_normal(z0.size), b[:, 0], b[:, 1])
                  for _ in range(starts - 1)]
    nm = [minimize(gamma, z, method="Nelder-Mead", bounds=list(map(tuple, b)),
                   options={"maxfev": maxfev, "xatol": 1e-8, "fatol": 1e-10}).fun for z in z0s]
    res = hinfstruct(P, [K], starts=starts, seed=seed)
    print(f"loop-shaping index, order-2 K, {starts} starts")
    print(f"  Nelder-Mead  gamma {min(nm):.5f} .. {max(nm):.5f}   ({count[0]} exact norms)")
    found = [run["gamma"] for run in res.runs]
    print(f"  hinfstruct   gamma {min(found):.5f} .. {max(found):.5f}   ({res.nfev} exact norms)")
    return {"Nelder-Mead": [float(v) for v in nm], "hinfstruct": found}


def requirements(structure: str, starts: int, maxfev: int, plants: int, seed: int) -> None:
    """Table 2: tune's two searches at equal evaluations per start."""
    robot = load_robot("rrr")
    reqs = [make_requirement(t) for t in ("delay_margin=0.006", "error_ratio=10",
                                          "actuator_bandwidth=300,delay=0.002")]
    print(f"tune {structure}, {plants} plants, {starts} starts, {maxfev} evaluations per start")
    out = {}
    for search in ("nelder-mead", "minimax"):
        res = tune(robot, make_structure(structure, None), reqs, plants=plants, starts=starts,
                   verify=False, search=search, maxfev=maxfev, seed=seed)
        each = ", ".join(f"{s['objective']:.4f}" for s in res.starts)
        print(f"  {search:12s} worst normalized {res.objective:.4f}   (starts: {each})")
        out[search] = [s["objective"] for s in res.starts]
    return out


def draw(index: dict, tuned: dict, structure: str, path: str) -> None:
    """Two panels, one bar per start and search: gamma, and the worst normalized value."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    panels = ((axes[0], index, "loop-shaping index gamma [-]",
               "Paper's loop-shaping index, order-2 K (lam = 45 rad/s)"),
              (axes[1], tuned, "worst normalized requirement [-]",
               f"tune, {structure}: the same evaluations per start"))
    for ax, data, ylabel, title in panels:
        starts = np.arange(len(next(iter(data.values()))))
        for k, (name, values) in enumerate(data.items()):
            ax.bar(starts + 0.4 * k - 0.2, values, width=0.4, label=name)
        ax.set_yscale("log")
        ax.set_xticks(starts, [str(i + 1) for i in starts])
        ax.set_xlabel("start")
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10)
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def main(argv=None) -> None:
    """Parse the options and print both tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--starts", type=int, default=3, help="starts of each search (3)")
    p.add_argument("--maxfev", type=int, default=300,
                   help="evaluations per start of tune's searches (300)")
    p.add_argument("--nm-maxfev", type=int, default=1000,
                   help="exact norms per start of Nelder-Mead on the index (1000)")
    p.add_argument("--plants", type=int, default=5, help="uncertain plants of tune (5)")
    p.add_argument("--structure", default="pid", help="tune's structure (pid; or order2)")
    p.add_argument("--seed", type=int, default=1, help="seed of the starts and plants (1)")
    p.add_argument("--out", default="compare_searches.png", help="figure (PNG) to write")
    args = p.parse_args(argv)
    index = loop_shaping(args.starts, args.nm_maxfev, args.seed)
    tuned = requirements(args.structure, args.starts, args.maxfev, args.plants, args.seed)
    draw(index, tuned, args.structure, args.out)


if __name__ == "__main__":
    main()
