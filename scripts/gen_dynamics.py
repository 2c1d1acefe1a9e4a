#!/usr/bin/env python
"""Write (or check) the committed parameter-input dynamics ``_ext/generated/dyn_<name>.c``.
========================================================================================

One file per generated structure (:data:`rrr_pin.sim.batched.GENERATED`: the RRR, UR5 and
Panda with its fingers locked), made by the hand-written generator :mod:`rrr_pin.sim.dyngen`
from the structure alone (joint types and tree; no number of the model enters the code).

Usage::

    scripts/gen_dynamics.py            # rewrite the files
    scripts/gen_dynamics.py --check    # exit 1 if a committed file differs from the generator

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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true",
                        help="exit 1 if a committed file differs from the generator's output")
    args = parser.parse_args(argv)
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
