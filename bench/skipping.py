"""Suite ``skipping``: the CPU the compiler's pruning saves on each shipped graph, and quiet vs busy scenes.

(1) Every shipped graph compiled twice, as shipped (pruned) and with ``compile_graph(graph,
    prune=False)`` (forced-full: every node started, every output computed, every connected input
    fed), both run in this process with ``--fast`` semantics (InprocExecutor, virtual clock,
    recorder discarding), repeats interleaved; the figure is process CPU seconds per graph second.
    The recorded streams of the two runs must be identical (pruning must not change a result).
(2) CPU on a quiet scene (no contact) against a busy one (contact) for the touch graph and for the
    teleoperation force estimators (tactip_sim → crop → ssim → linear_force, and → cnn_force), and
    what a run-time gate could save there: the share of the chain's CPU the estimator takes, how
    often a frame equals the previous one (an exact "unchanged frame" gate), and the force error a
    "reuse the last value" gate would make on the quiet scene.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from flowtact.benchmark import Context, Suite

GRAPHS = ("touch", "slip", "teleop", "teleop_cnn", "tactip_dataset")
#: Overrides per graph for a --fast run: the exoskeleton emulator on a pseudo-terminal needs a
#: real-time run (serial_io refuses to run ahead of the wall clock), so the teleop graphs use the
#: in-process exoskeleton simulation (``port: sim``) here.
FAST_OVERRIDES = {"teleop": ["exo.port=sim"], "teleop_cnn": ["exo.port=sim"]}
#: Graphs with a 2 ms tick (their feedback loop): fewer graph seconds and repeats.
LOOPS = ("teleop", "teleop_cnn")
UNIT = "CPU s per graph s"
#: teleop.yaml's linear fit, the force per unit of SSIM (N), to turn an SSIM error into newtons.
SSIM_SLOPE_N = (-23.2, -19.1, -22.3)
SSIM_INTERCEPT_N = (19.8, 16.4, 18.9)


class _Discard:
    """A recorder that keeps nothing (both plans pay the same recording cost: none)."""

    def write(self, stream: str, chunk: Any) -> None:
        pass

    def maybe_flush(self) -> None:
        pass


class _Keep(_Discard):
    """A recorder that keeps every chunk, to compare two runs' recorded streams."""

    def __init__(self) -> None:
        self.chunks: dict[str, list[Any]] = {}

    def write(self, stream: str, chunk: Any) -> None:
        self.chunks.setdefault(stream, []).append(chunk)

    def joined(self, stream: str) -> tuple[np.ndarray, np.ndarray]:
        cs = self.chunks.get(stream, [])
        if not cs:
            return np.empty(0), np.empty(0)
        return np.concatenate([c.t for c in cs]), np.concatenate([c.data for c in cs])


def _tick(plan: Any) -> float | None:
    from flowtact.running.launch import has_feedback
    from flowtact.runtime.clock import DEFAULT_TICK_REALTIME_S

    return plan.graph.tick_s or (DEFAULT_TICK_REALTIME_S if has_feedback(plan) else None)


def cpu_per_graph_second(
    plan: Any, seconds: float, recorder: Any = None, tick_s: float | None = None
) -> float:
    """Process CPU seconds (``time.process_time``: every thread of this process, not its children)
    spent running ``plan`` in process on the virtual clock for ``seconds`` of graph time, per graph
    second. Building and binding the blocks is not counted; ``tick_s`` overrides the graph's tick."""
    from flowtact.runtime.inproc import InprocExecutor

    ex = InprocExecutor(plan, fast=True, tick_s=tick_s or _tick(plan), recorder=recorder or _Discard())
    c0 = time.process_time()
    ex.run(seconds)
    return (time.process_time() - c0) / seconds


def paired_cpu(
    plans: dict[str, Any], seconds: float, repeats: int, tick_s: float | None = None
) -> dict[str, list[float]]:
    """CPU per graph second of each plan, ``repeats`` times, interleaved (load drifts hit both),
    after one short warm-up run each (numba compilation, model loading, caches)."""
    for plan in plans.values():
        cpu_per_graph_second(plan, min(seconds, 0.5), tick_s=tick_s)
    out: dict[str, list[float]] = {k: [] for k in plans}
    for _ in range(repeats):
        for k, plan in plans.items():
            out[k].append(cpu_per_graph_second(plan, seconds, tick_s=tick_s))
    return out


def same_records(a: Any, b: Any, seconds: float) -> tuple[bool, str]:
    """Run two plans once each with a keeping recorder; are all recorded streams bit-identical?"""
    ra, rb = _Keep(), _Keep()
    cpu_per_graph_second(a, seconds, ra)
    cpu_per_graph_second(b, seconds, rb)
    streams = sorted(f"{n}.{p}" for n, p in a.record)
    diff = []
    for s in streams:
        (ta, da), (tb, db) = ra.joined(s), rb.joined(s)
        if not (np.array_equal(ta, tb) and np.array_equal(da, db, equal_nan=True)):
            diff.append(s)
    return not diff, (f"differ: {', '.join(diff)}" if diff else f"{len(streams)} streams identical")


def skipped_parts(plan: Any) -> str:
    """What the pruned plan leaves out, in words (nodes not started, inputs not fed, outputs not computed)."""
    parts = []
    if plan.pruned:
        parts.append("not started: " + ", ".join(f"`{n}`" for n in plan.pruned))
    inputs = sorted(n.split(":")[0] for n in plan.notes if "not demanded" in n)
    if inputs:
        parts.append("inputs not fed: " + ", ".join(f"`{i}`" for i in inputs))
    outputs = [n.split(": outputs ")[0] + "." + n.split(": outputs ")[1].split(" not")[0]
               for n in plan.notes if ": outputs " in n]  # fmt: skip
    if outputs:
        parts.append("outputs not computed: " + "; ".join(f"`{o}`" for o in sorted(outputs)))
    return "; ".join(parts) or "nothing"


# -- (1) pruned vs forced-full ----------------------------------------------------------------------


#: The real-time tick (5 ms): a live run's per-node-step overhead, which a node not started saves.
LIVE_TICK_S = 0.005


def _variants(name: str, quick: bool) -> list[tuple[str, float, float | None]]:
    """(label, graph seconds, tick override) to measure a graph with: its own tick, and for the
    Rager graphs also the live 5 ms tick on the virtual clock."""
    if name in LOOPS:
        return [(name, 1.5 if quick else 5.0, None)]
    if name == "tactip_dataset":
        return [(name, 3.0 if quick else 15.0, None)]
    return [
        (name, 15.0 if quick else 60.0, None),
        (f"{name} @ 5 ms tick", 3.0 if quick else 10.0, LIVE_TICK_S),
    ]


def pruning(ctx: Context) -> list[dict[str, Any]]:
    from flowtact.errors import GraphFileError
    from flowtact.graphfile.graph import load_graph, resolve_graph_path
    from flowtact.running.compile import compile_graph

    rows = []
    for name in GRAPHS:
        graph = load_graph(resolve_graph_path(name), overrides=FAST_OVERRIDES.get(name, ()))
        try:
            pruned, full = compile_graph(graph), compile_graph(graph, prune=False)
        except GraphFileError as e:  # a missing extra (torch for teleop_cnn)
            ctx.note(f"`{name}` not measured: {str(e).splitlines()[0]}")
            continue
        for label, seconds, tick in _variants(name, ctx.quick):
            ctx.step(f"pruned vs full: {label}")
            repeats = 3 if name in LOOPS and ctx.quick else ctx.repeats
            cpu = paired_cpu({"full": full, "pruned": pruned}, seconds, ctx.share(repeats), tick)
            params = {"graph": name, "graph_seconds": seconds, "tick_s": tick or _tick(pruned)}
            base = ctx.figure(
                f"{label}: forced-full", cpu["full"], UNIT, "lower", is_baseline=True, params=params
            )
            fig = ctx.figure(
                f"{label}: pruned",
                cpu["pruned"],
                UNIT,
                "lower",
                baseline=base.key,
                paired=True,
                params=params,
            )
            rows.append({"graph": label, "skipped": skipped_parts(pruned), "pruned_nodes": list(pruned.pruned),
                         "seconds": seconds, "pruned": fig.median, "full": base.median,
                         "ratio": fig.median / base.median, "ratio_range": fig.ratio_range})  # fmt: skip
        if not ctx.partial:  # a verdict, not a timing: the runner's own process gives it
            same, detail = same_records(pruned, full, 1.0 if name in LOOPS else 3.0)
            ctx.check(f"{name}: pruned and forced-full runs record the same streams", same, detail)
    return rows


def pruning_note(rows: list[dict[str, Any]]) -> str:
    """Where pruning saved CPU beyond the spread, and where it did not, in one sentence each."""
    saved = [r for r in rows if r["ratio_range"] and r["ratio_range"][0] > 1.0]
    flat = [r for r in rows if r not in saved]
    parts = []
    if saved:
        parts.append("Pruning saved CPU beyond the spread on " + ", ".join(
            f"{r['graph']} ({100 * (1 - r['ratio']):.0f} %)" for r in saved))  # fmt: skip
    if flat:
        parts.append("pruning saved nothing measurable (the ratio's range includes 1) on " + ", ".join(
            f"{r['graph']} (pruned/full {r['ratio']:.2f})" for r in flat))  # fmt: skip
    return (
        "; ".join(parts).capitalize()[:1]
        + "; ".join(parts)[1:]
        + ". What is pruned in the shipped graphs is cheap: one 5-sample FIR at 1 kHz "
        "(`ddforce`) and a few unused outputs. The '@ 5 ms tick' rows run the same graph with the live tick "
        "on the virtual clock, where the executor's per-node-step cost is paid 200 times per graph second "
        "instead of once."
    )


def draw_pruning(rows: list[dict[str, Any]]):
    def draw(fig) -> None:  # type: ignore[no-untyped-def]
        cols = min(4, len(rows))
        nrows = -(-len(rows) // cols)
        axes = np.atleast_1d(fig.subplots(nrows, cols)).ravel()
        fig.set_size_inches(3.3 * cols, 3.6 * nrows)
        for ax, r in zip(axes, rows, strict=False):
            ax.bar(["forced-full", "pruned"], [r["full"] * 1e3, r["pruned"] * 1e3], color=["C7", "C0"])
            ax.set_title(f"{r['graph']}\npruned/full = {r['ratio']:.2f}", fontsize=9)
            ax.set_ylabel("CPU ms per graph second")
            ax.set_xlabel("not started: " + (", ".join(r["pruned_nodes"]) or "no node (unused outputs only)"),
                          fontsize=8)  # fmt: skip
            ax.tick_params(axis="x", labelsize=8)
            ax.grid(True, axis="y", alpha=0.3)
        for ax in axes[len(rows) :]:
            ax.set_visible(False)
        fig.tight_layout()

    return draw


# -- (2) quiet vs busy ------------------------------------------------------------------------------

VISION = """
name: vision_{est}
seed: 4
nodes:
  cams:  {{block: tactip_sim, params: {{scenario: {scenario}, noise_dn: {noise}}}}}
{estimator}
edges:
{edges}
record: [cams.frames, {out}]
"""
SSIM_NODES = f"""  crop:  {{block: crop}}
  ssim:  {{block: ssim}}
  force: {{block: linear_force, params: {{slope_n: {list(SSIM_SLOPE_N)}, intercept_n: {list(SSIM_INTERCEPT_N)}}}}}"""
SSIM_EDGES = "  - cams.frames -> crop.x\n  - crop.y -> ssim.x\n  - ssim.y -> force.x"
CNN_NODES = "  cnn:   {block: cnn_force}"
CNN_EDGES = "  - cams.frames -> cnn.x"


def vision_graph(est: str, scenario: str, noise: float = 3.0) -> Any:
    """tactip_sim (``taps``: busy, ``rest``: quiet) into the SSIM + linear fit or the CNN estimator."""
    from flowtact.graphfile.graph import load_graph

    nodes, edges, out = (
        (SSIM_NODES, SSIM_EDGES, "ssim.y, force.y") if est == "ssim" else (CNN_NODES, CNN_EDGES, "cnn.y")
    )
    text = VISION.format(est=est, scenario=scenario, noise=noise, estimator=nodes, edges=edges, out=out)
    return load_graph(f"<skipping:{est}:{scenario}>", text=text)


def gate_figures(frames: np.ndarray, ssim: np.ndarray) -> dict[str, float]:
    """What a gate on the quiet frames could do: the fraction of frames equal to the previous one
    (an exact gate's hit rate), the largest pixel change between consecutive frames (DN), and the
    largest force error (N) of reusing the previous frame's SSIM instead of computing it. The first
    frame (the reference) is left out."""
    frames, ssim = frames[1:], ssim[1:]  # the first frame is the reference itself (SSIM exactly 1)
    if len(frames) < 2:
        return {
            "equal_fraction": float("nan"),
            "max_pixel_change_dn": float("nan"),
            "reuse_error_n": float("nan"),
        }
    f = frames.reshape(len(frames), -1)
    equal = np.all(f[1:] == f[:-1], axis=1)
    change = np.abs(f[1:].astype(np.int16) - f[:-1].astype(np.int16)).max(axis=1)
    reuse = np.abs(np.diff(ssim, axis=0)) * np.abs(np.asarray(SSIM_SLOPE_N))
    return {"equal_fraction": float(equal.mean()), "max_pixel_change_dn": float(change.max()),
            "reuse_error_n": float(reuse.max())}  # fmt: skip


def _ssim_share(ctx: Context, seconds: float) -> dict[str, float]:
    """CPU of the ssim block alone on the quiet scene's cropped frames, per graph second (the most
    an SSIM gate could save), and the gate figures with and without sensor noise."""
    from flowtact.blocks.teleop.ssim import Ssim
    from flowtact.errors import GraphFileError
    from flowtact.running.compile import compile_graph
    from flowtact.testing import run_offline

    out: dict[str, float] = {}
    for noise in (3.0, 0.0):
        plan = compile_graph(vision_graph("ssim", "rest", noise))
        rec = _Keep()
        cpu_per_graph_second(plan, seconds, rec)
        frames, ssim = rec.joined("cams.frames")[1], rec.joined("ssim.y")[1]
        for k, v in gate_figures(frames, ssim).items():
            out[f"{k}@{noise:g}"] = v
        if noise:
            from flowtact.blocks.teleop.image import Crop

            crop = run_offline(Crop(), x=frames, rate_hz=40.0, units={"x": "DN"})["y"].data
            fig = ctx.duration("ssim block alone, quiet frames", lambda crop=crop: run_offline(
                Ssim(), x=crop, rate_hz=40.0, units={"x": "DN"}), scale=1.0 / seconds, unit=UNIT, repeats=3)  # fmt: skip
            out["ssim_alone"] = fig.median
            out["ssim_rest_force_n"] = float(np.abs(rec.joined("force.y")[1][1:]).mean())
    try:
        rec = _Keep()
        cpu_per_graph_second(compile_graph(vision_graph("cnn", "rest")), seconds, rec)
        out["cnn_rest_force_n"] = float(np.abs(rec.joined("cnn.y")[1]).mean())
    except GraphFileError:  # no torch: the CNN half of the verdict is left out
        out["cnn_rest_force_n"] = float("nan")
    return out


def quiet_busy(ctx: Context) -> tuple[list[dict[str, Any]], dict[str, float]]:
    from flowtact.errors import GraphFileError
    from flowtact.graphfile.graph import load_graph, resolve_graph_path
    from flowtact.running.compile import compile_graph

    cases: list[tuple[str, Any, Any, float]] = []
    touch = resolve_graph_path("touch")
    cases.append(("touch.yaml", load_graph(touch), load_graph(touch, overrides=["sensor.scenario=rest"]),
                  15.0 if ctx.quick else 60.0))  # fmt: skip
    vis_s = 3.0 if ctx.quick else 10.0
    cases.append(
        ("tactip_sim → SSIM + linear fit", vision_graph("ssim", "taps"), vision_graph("ssim", "rest"), vis_s)
    )
    cases.append(("tactip_sim → CNN", vision_graph("cnn", "taps"), vision_graph("cnn", "rest"), vis_s))
    rows = []
    for label, busy_g, quiet_g, seconds in cases:
        ctx.step(f"quiet vs busy: {label}")
        try:
            busy, quiet = compile_graph(busy_g), compile_graph(quiet_g)
        except GraphFileError as e:
            ctx.note(f"{label}: not measured: {str(e).splitlines()[0]}")
            continue
        cpu = paired_cpu({"busy": busy, "quiet": quiet}, seconds, ctx.share(ctx.repeats))
        base = ctx.figure(f"{label}: busy", cpu["busy"], UNIT, "lower", is_baseline=True)
        fig = ctx.figure(f"{label}: quiet", cpu["quiet"], UNIT, "lower", baseline=base.key, paired=True)
        rows.append({"scene": label, "busy": base.median, "quiet": fig.median, "ratio": fig.median / base.median,
                     "seconds": seconds})  # fmt: skip
    ctx.step("what an SSIM gate could skip")
    gate = _ssim_share(ctx, vis_s)
    ctx.data["gate"] = gate
    return rows, gate


def draw_quiet_busy(rows: list[dict[str, Any]]):
    def draw(fig) -> None:  # type: ignore[no-untyped-def]
        axes = fig.subplots(1, len(rows))
        fig.set_size_inches(3.2 * len(rows) + 1, 4.0)
        for ax, r in zip(np.atleast_1d(axes), rows, strict=True):
            ax.bar(
                ["busy (contact)", "quiet (no contact)"],
                [r["busy"] * 1e3, r["quiet"] * 1e3],
                color=["C3", "C2"],
            )
            ax.set_title(f"{r['scene']}\nquiet/busy = {r['ratio']:.2f}", fontsize=9)
            ax.set_ylabel("CPU ms per graph second")
            ax.tick_params(axis="x", labelsize=8)
            ax.grid(True, axis="y", alpha=0.3)
        fig.tight_layout()

    return draw


def run(ctx: Context) -> None:
    rows = pruning(ctx)
    ctx.data["pruning"] = rows
    ctx.table(
        "Pruned vs forced-full plans, in process with --fast semantics (CPU s per graph second, medians)",
        ["graph", "what the compiler skips", "graph s per run", "forced-full", "pruned", "pruned/full", "CPU saved"],
        [[r["graph"], r["skipped"], r["seconds"], f"{r['full']:.4g}", f"{r['pruned']:.4g}", f"{r['ratio']:.3f}",
          f"{100 * (1 - r['ratio']):.1f} %"] for r in rows],
        "Process CPU (time.process_time) of InprocExecutor.run over the same graph seconds, repeats interleaved; "
        "forced-full = compile_graph(graph, prune=False). teleop and teleop_cnn run with exo.port=sim (the "
        "exoskeleton simulated in process: the emulator on a pseudo-terminal needs a real-time run).",
    )  # fmt: skip
    if rows:
        ctx.plot(
            "pruning", draw_pruning(rows), "CPU per graph second, forced-full vs pruned, per shipped graph"
        )
    qb, gate = quiet_busy(ctx)
    ctx.data["quiet_busy"] = qb
    ctx.table(
        "Quiet (no contact) vs busy (contact) scenes (CPU s per graph second, medians)",
        ["scene", "busy", "quiet", "quiet/busy"],
        [[r["scene"], f"{r['busy']:.4g}", f"{r['quiet']:.4g}", f"{r['ratio']:.3f}"] for r in qb],
        "touch.yaml quiet: sensor.scenario=rest; vision quiet: tactip_sim scenario rest, busy: taps (40 FPS, 3 sensors).",
    )
    if qb:
        ctx.plot("quiet_busy", draw_quiet_busy(qb), "CPU per graph second on a busy and a quiet scene")
    ctx.table(
        "What a run-time gate in SSIM could skip on the quiet scene",
        ["sensor noise", "frames equal to the previous one", "largest pixel change between frames (DN)",
         "force error of reusing the last SSIM (N)"],
        [[f"σ = {n} DN", f"{100 * gate[f'equal_fraction@{n}']:.1f} %", f"{gate[f'max_pixel_change_dn@{n}']:.0f}",
          f"{gate[f'reuse_error_n@{n}']:.3g}"] for n in ("3", "0")],
        f"The ssim block alone costs {gate['ssim_alone']:.4g} CPU s per graph second on these frames: the most an "
        "SSIM gate could save. The first frame (the reference) is left out.",
    )  # fmt: skip
    if rows:
        ctx.note(pruning_note(rows))
    ctx.note(gate_note(qb, gate))


def gate_note(qb: list[dict[str, Any]], gate: dict[str, float]) -> str:
    """The verdict on a run-time gate, from this run's numbers."""
    vision = next((r for r in qb if r["scene"].startswith("tactip_sim → SSIM")), None)
    share = f"{100 * gate['ssim_alone'] / vision['quiet']:.0f} %" if vision else "?"
    rest = gate["ssim_rest_force_n"]
    return (
        f"No run-time gate was added. On the quiet scene with the emulated camera's noise (σ = 3 DN) an exact "
        f"unchanged-frame gate in ssim would fire on {100 * gate['equal_fraction@3']:.0f} % of frames (pixels move "
        f"by up to {gate['max_pixel_change_dn@3']:.0f} DN between frames), and reusing the last SSIM instead of "
        f"computing it would be off by up to {gate['reuse_error_n@3']:.2g} N ({gate['reuse_error_n@3'] / rest:.1f}× "
        f"the SSIM fit's mean |force| at rest, {rest:.2g} N). Only a noise-free camera (σ = 0: "
        f"{100 * gate['equal_fraction@0']:.0f} % equal frames) would let a gate skip the ssim block's {share} of the "
        "vision chain's CPU. A no-contact gate for the CNN would have to emit a value the network does not compute "
        f"(its mean |output| at rest: {gate['cnn_rest_force_n']:.2g} N), and nlif integrates every step whatever "
        "the drive (its state decays), so neither was added either; see the quiet/busy table for what a quiet "
        "scene already saves without a gate."
    )


SUITE = Suite(
    name="skipping",
    title="What skipping saves: pruned vs forced-full plans, quiet vs busy scenes",
    measures="For every shipped graph, the parts the compiler prunes (nodes not started, inputs not fed, outputs "
    "not computed) and the process CPU per graph second of the pruned plan against the same graph compiled with "
    "`prune=False`, both in process with --fast semantics; then CPU on a quiet scene (no contact) against a busy "
    "one, and what a run-time gate (skip an unchanged frame) could save.",
    baseline="the forced-full plan (`compile_graph(graph, prune=False)`), resp. the busy scene, in the same run",
    run=run,
    minutes_quick=0.6,
    minutes_full=2.5,
)
