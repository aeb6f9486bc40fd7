"""Digest what every shipped graph records in a short deterministic run, to prove a change kept them.

Each graph in graphs/ runs as ``flowtact run GRAPH --fast --inproc --duration S --record …`` (a
serial device in its graph-time ``sim`` mode, so nothing depends on the wall clock); every
recorded stream's time stamps and data are hashed (SHA-256 of the raw bytes, dtype and shape).
With ``--processes`` each graph runs across processes instead (no ``--inproc``: one worker per
process group, joined by ZeroMQ), which ``--fast`` makes deterministic too.

    python scripts/graph_digests.py > before.json        # at the commit before a change
    python scripts/graph_digests.py --compare before.json  # after it: exit 1 on any difference
    python scripts/graph_digests.py --processes --compare before-processes.json
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import yaml

from flowtact.recording.hdf5 import read_recording

ROOT = Path(__file__).resolve().parent.parent
DURATION_S = 3.0


def _overrides(graph: Path) -> list[str]:
    """Put every serial device of the graph in its deterministic, graph-time ``sim`` mode."""
    doc = yaml.safe_load(graph.read_text())
    return [f"{name}.port=sim" for name, node in doc["nodes"].items() if node.get("block") == "serial_io"]


#: Blocks that talk to live streams on the network (LSL): a graph holding one is not digested
#: (tests/blocks/devices/test_lsl_interop.py runs graphs/lsl_touch.yaml against real peers).
LIVE_BLOCKS = {"lsl_inlet", "lsl_outlet"}


def _live(graph: Path) -> bool:
    doc = yaml.safe_load(graph.read_text())
    return any(node.get("block") in LIVE_BLOCKS for node in doc["nodes"].values())


def _digest(*arrays) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def digests(graph: Path, duration_s: float = DURATION_S, *, processes: bool = False) -> dict[str, str]:
    """Stream name -> digest of what ``graph`` records in a ``--fast --inproc`` run (``processes``:
    a ``--fast`` run across processes)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run.h5"
        sets = [a for o in _overrides(graph) for a in ("--set", o)]
        mode = [] if processes else ["--inproc"]
        cmd = [sys.executable, "-m", "flowtact.cli", "run", str(graph), "--fast", *mode, "--quiet"]
        cmd += ["--duration", str(duration_s), "--record", str(out), *sets]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        rec = read_recording(out)
        return {name: _digest(s.t, s.data) for name, s in sorted(rec.streams.items())}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--compare", metavar="JSON", help="digests from before; exit 1 where they differ")
    ap.add_argument("--duration", type=float, default=DURATION_S, help="graph seconds per run")
    ap.add_argument("--processes", action="store_true", help="run across processes, not --inproc")
    args = ap.parse_args(argv)
    got = {
        g.stem: digests(g, args.duration, processes=args.processes)
        for g in sorted((ROOT / "graphs").glob("*.yaml"))
        if not _live(g)
    }
    if not args.compare:
        json.dump(got, sys.stdout, indent=1, sort_keys=True)
        print()
        return 0
    before = json.loads(Path(args.compare).read_text())
    bad = [
        f"{g}: {s}"
        for g in sorted(set(before) | set(got))
        for s in sorted(set(before.get(g, {})) | set(got.get(g, {})))
        if before.get(g, {}).get(s) != got.get(g, {}).get(s)
    ]
    for line in bad:
        print(f"differs: {line}")
    n = sum(len(v) for v in got.values())
    mode = "across processes" if args.processes else "in-process"
    print(f"{n - len(bad)} of {n} recorded streams identical across {len(got)} graphs ({mode})")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
