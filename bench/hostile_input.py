"""Hostile inputs: wall time and peak RSS of `flowtact validate` refusing each one (50 MB file, alias
bomb, 5 000 nested lists, /dev/zero, a FIFO, a population of 1e14 neurons, ...).

Each case runs in a fresh child Python (interpreter start and flowtact's imports included), which
reports its own peak resident set size. The cases are those of tests/test_hostile_input.py
(tests/hostile.py), where the refusal, its place and the 500 MiB bound are asserted.

    python bench/hostile_input.py [--repeats 3] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))  # the cases live with the tests
from hostile import CASES, run_measured


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3, help="runs per case (the slowest and largest are kept)")
    ap.add_argument("--json", help="also write the figures as JSON")
    args = ap.parse_args(argv)
    rows = {}
    print(f"{'case':<22} {'exit':>4} {'max wall s':>10} {'max peak MiB':>12}  refusal")
    for name, case in CASES.items():
        runs = []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as folder:
                cli_args, expect = case(Path(folder))
                m = run_measured(cli_args)
                runs.append((m, expect in m.stderr))
        worst_s = max(m.seconds for m, _ in runs)
        worst_mib = max(m.peak_mib for m, _ in runs)
        ok = all(found and m.returncode == 2 for m, found in runs)
        first = runs[0][0].stderr.splitlines()[0] if runs[0][0].stderr else ""
        rows[name] = {"seconds": worst_s, "peak_mib": worst_mib, "refused_as_expected": ok}
        print(f"{name:<22} {runs[0][0].returncode:>4} {worst_s:>10.2f} {worst_mib:>12.1f}  {first[:90]}")
    print(
        f"max over cases: {max(r['seconds'] for r in rows.values()):.2f} s, "
        f"{max(r['peak_mib'] for r in rows.values()):.1f} MiB peak RSS; "
        f"all refused as expected: {all(r['refused_as_expected'] for r in rows.values())}"
    )
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2))
    return 0 if all(r["refused_as_expected"] for r in rows.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
