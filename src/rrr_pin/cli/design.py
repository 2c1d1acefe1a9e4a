"""``rrr-pin design``: the H-infinity loop-shaping design of the paper's section 4."""

from __future__ import annotations

from .common import claim_out, control_ss, option
from .options import add_overwrite

__all__ = ["add", "run_design"]


def add(sub) -> None:
    """Declare ``design``."""
    p = sub.add_parser("design", help="H-infinity loop-shaping design of the paper's section 4")
    p.add_argument("--lam", type=float, default=45.0,
                   help="feedback-linearization natural frequency lambda [rad/s] (default 45)")
    p.add_argument("--factor", type=float, default=1.0,
                   help="gamma / gamma_min of ncfsyn, 1 = optimal (default 1.0)")
    p.add_argument("--joints", type=int, default=3,
                   help="size n of the diagonal MIMO plant and controller (default 3)")
    p.add_argument("--order", type=int, default=2, metavar="N",
                   help="states of the reduced controller, eq. (18) (2, the paper's)")
    p.add_argument("--out", metavar="DIR", default=None,
                   help="write fig2.png, fig3.png, fig4a.png, fig4b.png and margins.png (the "
                        "loop G K: singular values, Bode phase, Nyquist) into DIR")
    add_overwrite(p)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=run_design)


def run_design(args) -> int:
    """Design, print (or ``--json``) and optionally draw the loop-shaping controller."""
    if args.out is not None:  # before the design and its imports: --out /proc/x refused at once
        claim_out(args, "design")
    from ..report.design import design_lines, design_summary
    from ..report.jsondata import dumps
    from ..robust.loopshaping import design
    from ..validation import FieldError

    try:
        d = design(lam=args.lam, n=args.joints, factor=args.factor, order=args.order)
    except FieldError as exc:  # design's lam, n, factor are --lam, --joints, --factor
        raise exc.relabelled(lambda f: "--joints" if f == "n" else option(f)) from None
    figures = []
    if args.out is not None:
        from ..report.margins import design_loop_title, save_margins_figure
        from ..report.plotting import save_design_figures

        figures = [str(f) for f in save_design_figures(d, args.out)]
        # the design's own loop, G K (eq. 11 plant, eq. 18 controller): margins.png
        figures.append(str(save_margins_figure({"G K": control_ss(d.G * d.K)}, args.out,
                                               title=design_loop_title(d))))
    if args.json:
        print(dumps({**design_summary(d), **({"figures": figures} if figures else {})}))
        return 0
    print("\n".join(design_lines(d) + [f"wrote {f}" for f in figures]))
    return 0
