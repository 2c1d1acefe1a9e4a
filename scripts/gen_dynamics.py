#!/usr/bin/env python
"""Write (or check) the committed parameter-input dynamics ``_ext/generated/dyn_<name>.c``.
========================================================================================

One file per generated structure (:data:`rrr_pin.sim.batched.GENERATED`: the RRR, UR5 and
Panda with its fingers locked), made by the hand-written generator :mod:`rrr_pin.sim.dyngen`
from the structure alone (joint types and tree; no number of the model enters the code).

Usage::

    scripts/gen_dynamics.py            # rewrite the files
    scripts/gen_dynamics.py --check    # exit 1 if a committed file differs from the generator
    scripts/gen_dynamics.py --counts   # operations per call of each structure, next to
                                       # Featherstone's count for the ABA

A developer tool (pure Python, about 1 s); ``pip install .`` compiles the committed C.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EXT = ROOT / "src" / "rrr_pin" / "_ext" / "generated"


def expected() -> dict:
    """``{path: text}`` the generator writes today."""
    from rrr_pin.model.dynamics import load_robot
    from rrr_pin.sim import dyngen
    from rrr_pin.sim.batched import GENERATED

    out = {}
    for name, (source, lock) in GENERATED.items():
        model = load_robot(source, lock=dict(lock)).model
        label = source + (f" with {', '.join(f'{k}={v:g}' for k, v in lock)} locked"
                          if lock else "")
        out[EXT / f"dyn_{name}.c"] = dyngen.generate(name, model, source=label)
    return out


def counts() -> list[dict]:
    """Operations per plant and call of each generated structure (rrr_pin.sim.dyngen)."""
    from rrr_pin.model.dynamics import load_robot
    from rrr_pin.sim import dyngen
    from rrr_pin.sim.batched import GENERATED

    rows = []
    for name, (source, lock) in GENERATED.items():
        model = load_robot(source, lock=dict(lock)).model
        now, before = dyngen.operation_counts(model), dyngen.operation_counts(model,
                                                                              hoisted=False)
        rows.append({"structure": name, "nq": model.nq, "fd": dyngen.fd_algorithm(now),
                     "featherstone_aba": dyngen.featherstone_aba_operations(model.nq),
                     **{f"{k}_unhoisted": v["total"] for k, v in before.items() if k != "pre"},
                     **{k: v["total"] for k, v in now.items()}})
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if a committed file differs from the generator's output")
    parser.add_argument("--counts", action="store_true",
                        help="print the operations (+, -, *, /) per plant and call of each "
                             "structure's functions, before and after hoisting, next to "
                             "Featherstone's count for the ABA, and the inverse dynamics (id) the "
                             "FL law runs; write nothing")
    args = parser.parse_args(argv)
    if args.counts:
        print(f"{'structure':10}{'nq':>3}{'crba':>11}{'nle':>6}{'ldlt':>12}{'aba':>12}"
              f"{'Featherstone ABA':>18}{'pre':>6}{'id':>6}  fd")
        for r in counts():
            print(f"{r['structure']:10}{r['nq']:>3}{r['crba_unhoisted']:>5} -> {r['crba']:<4}"
                  f"{r['nle']:>5} {r['ldlt_unhoisted']:>5} -> {r['ldlt']:<4}"
                  f"{r['aba_unhoisted']:>5} -> {r['aba']:<4}{r['featherstone_aba']:>18}"
                  f"{r['pre']:>6}{r['id']:>6}  {r['fd']}")
        return 0
    stale = []
    for path, text in expected().items():
        if args.check:
            if not path.is_file() or path.read_text() != text:
                stale.append(path.name)
        else:
            path.write_text(text)
            print(f"wrote {path.relative_to(ROOT)} ({len(text.splitlines())} lines)")
    if stale:
        print(f"stale: {', '.join(stale)}; run scripts/gen_dynamics.py", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
