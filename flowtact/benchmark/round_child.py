"""One child of :mod:`flowtact.benchmark.process_rounds`: runs its part of a suite and writes the raw
samples of every figure as JSON (``python -m flowtact.benchmark.round_child SUITE --part I --parts N
--out FILE``).

A module of its own so that the parent's side (which the suite module uses for its shares and prior
samples) imports no suite, registry or runner: the child needs them all, the parent none.
"""

from __future__ import annotations

import argparse
import importlib
import json
import sys
from pathlib import Path

from flowtact.benchmark.machine import pin_threads
from flowtact.benchmark.process_rounds import STEP_MARK
from flowtact.benchmark.registry import Unavailable, suites
from flowtact.benchmark.suite import Context
from flowtact.errors import SuiteSkipped

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """A child: run one part of a suite and write its figures' raw samples as JSON."""
    ap = argparse.ArgumentParser(prog="python -m flowtact.benchmark.round_child")
    ap.add_argument("suite", help="a registered suite's name, or module:attribute of a Suite")
    ap.add_argument("--part", type=int, required=True)
    ap.add_argument("--parts", type=int, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--peers", action="store_true")
    a = ap.parse_args(argv)
    pin_threads()
    if ":" in a.suite:
        module, attr = a.suite.split(":", 1)
        suite = getattr(importlib.import_module(module), attr)
    else:
        suite = suites().get(a.suite)
    if suite is None or isinstance(suite, Unavailable):
        print(f"suite {a.suite!r} is not available here", flush=True)
        return 1
    ctx = Context(suite, a.quick, a.peers, on_step=lambda t: print(STEP_MARK + t, flush=True),
                  part=a.part, parts=a.parts)  # fmt: skip
    try:
        suite.run(ctx)
    except SuiteSkipped as e:
        print(f"skipped: {e}", flush=True)
        return 1
    a.out.write_text(json.dumps(ctx.raw_samples()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
