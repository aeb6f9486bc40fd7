"""Benchmark of the SSIM block: frames/s per core against scikit-image, and the block's step cost.

    python bench/blocks/teleop/ssim.py [--quick] [--json out.json]

(1) Kernel: mean SSIM of one uint8 frame against a fixed reference, frames/s on one core (threads
    pinned, median of repeats) for the thesis's cropped 90×240 frames and full 240×320 frames:
    flowtact float64 (the default), flowtact float32, and scikit-image's
    ``structural_similarity(win_size=7, gaussian_weights=False, data_range=255)`` — the oracle,
    the baseline measured in the same run. Frames: emulated TacTip images (``tactip_sim``'s renderer:
    30 pins on dark skin, vignetting, noise σ 3 DN) at 8 contact forces, as in ../shared/NUMERICS.md §2.
    flowtact is timed both batched (all frames in one kernel call) and one frame per call.
    Also the largest |flowtact − skimage| on those frames, and pass/fail against issue 4's bars
    (float64: ≥ 5 000 frames/s at 90×240, ≥ 1 500 at 240×320).
(2) Block: samples/s through ``Ssim.__call__`` (read-only views, reference logic, kernel, output
    chunk) with 3 sensors per sample, one sample per chunk (a live 40 Hz graph) and 40 per chunk;
    frames/s = 3 × samples/s.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402

import numpy as np  # noqa: E402

BENCH = Path(__file__).resolve().parents[2]  # bench/: its shared helpers (_timing)
if str(BENCH) not in sys.path:
    sys.path.insert(0, str(BENCH))

from _timing import median_time  # noqa: E402
from skimage.metrics import structural_similarity  # noqa: E402  (bench-only baseline)

from flowtact import Chunk, StreamSpec  # noqa: E402
from flowtact.blocks.teleop.image import centre_crop  # noqa: E402
from flowtact.blocks.teleop.ssim import Ssim, SsimReference  # noqa: E402
from flowtact.blocks.teleop.tactip_sim import pressed_frames  # noqa: E402

RATE = 40.0
LEVELS_N = (0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0)
SIZES = {"90x240": (90, 240), "240x320": (240, 320)}
#: Issue 4: SSIM >= 5 000 frames/s per core on 90×240 crops and >= 1 500 on full 240×320 frames.
BARS_FPS = {"90x240": 5000.0, "240x320": 1500.0}


def tactip_frames(size: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Reference (H, W) and one frame per contact force (8, H, W), uint8."""
    images = pressed_frames([0.0, *LEVELS_N], seed)[:, 0]
    if size == "90x240":
        images = np.ascontiguousarray(centre_crop(images))
    return images[0], images[1:]


def skimage_ssim(ref: np.ndarray, cur: np.ndarray) -> float:
    return structural_similarity(ref, cur, win_size=7, gaussian_weights=False, data_range=255)


# -- (1) kernel ---------------------------------------------------------------------------------------


def kernel(quick: bool) -> list[dict]:
    repeats = 3 if quick else 9
    rows = []
    for size in SIZES:
        ref, frames = tactip_frames(size)
        want = np.array([skimage_ssim(ref, f) for f in frames])
        batch = np.ascontiguousarray(np.tile(frames, (4 if quick else 16, 1, 1))[:, None])
        row: dict = {"size": size, "frames_per_run": len(batch)}
        for precision in ("float64", "float32"):
            r = SsimReference(ref[None], precision)
            got = r.compare(frames[:, None])[:, 0]
            row[f"err_{precision}"] = float(np.max(np.abs(got - want)))
            r.compare(batch[:1])  # warm-up (numba compile / cache load)
            row[f"fps_{precision}"] = len(batch) / median_time(lambda r=r, b=batch: r.compare(b), repeats)
            singles = [batch[i : i + 1] for i in range(len(batch))]

            def one_by_one(r=r, singles=singles) -> None:
                for s in singles:
                    r.compare(s)

            row[f"fps_{precision}_per_call"] = len(batch) / median_time(one_by_one, repeats)
        n_sk = len(frames) * (1 if quick else 2)

        def run_skimage(frames=frames, ref=ref, n_sk=n_sk) -> None:
            for i in range(n_sk):
                skimage_ssim(ref, frames[i % len(frames)])

        run_skimage()
        row["fps_skimage"] = n_sk / median_time(run_skimage, max(3, repeats // 3))
        row["ratio_float64"] = row["fps_float64"] / row["fps_skimage"]
        row["ratio_float32"] = row["fps_float32"] / row["fps_skimage"]
        row["bar_fps"] = BARS_FPS[size]
        row["pass"] = bool(row["fps_float64"] >= BARS_FPS[size])
        rows.append(row)
    return rows


def print_kernel(rows: list[dict]) -> None:
    print("\n(1) SSIM of one frame vs a fixed reference, frames/s on one core (median); ratio vs skimage")
    print(
        f"{'size':>8} | {'float64':>8} {'per call':>8} {'×sk':>6} {'max err':>8} | "
        f"{'float32':>8} {'per call':>8} {'×sk':>6} {'max err':>8} | {'skimage':>8} | bar (float64)"
    )
    for r in rows:
        verdict = "PASS" if r["pass"] else "FAIL"
        print(
            f"{r['size']:>8} | {r['fps_float64']:8.0f} {r['fps_float64_per_call']:8.0f} "
            f"{r['ratio_float64']:6.1f} {r['err_float64']:8.1e} | {r['fps_float32']:8.0f} "
            f"{r['fps_float32_per_call']:8.0f} {r['ratio_float32']:6.1f} {r['err_float32']:8.1e} | "
            f"{r['fps_skimage']:8.0f} | >= {r['bar_fps']:.0f}: {verdict}"
        )


# -- (2) block ----------------------------------------------------------------------------------------


def block(quick: bool) -> list[dict]:
    repeats = 3 if quick else 7
    rows = []
    for size, (h, w) in SIZES.items():
        ref, frames = tactip_frames(size, seed=1)
        stacks = np.stack([np.stack([f, f[::-1], f[:, ::-1]]) for f in frames])  # (8, 3, H, W)
        n = 40 if quick else 160
        data = np.ascontiguousarray(
            np.concatenate([np.stack([ref, ref[::-1], ref[:, ::-1]])[None]] + [stacks] * (n // 8))[:n]
        )
        t = np.arange(n) / RATE
        spec = {"x": StreamSpec(dtype="uint8", shape=(3, h, w), units="DN", rate_hz=RATE)}
        for chunk in (1, 40):
            for precision in ("float64", "float32"):
                b = Ssim(precision=precision)
                b.bind(spec)
                chunks = [
                    Chunk(t[i : i + chunk], data[i : i + chunk], float(t[min(i + chunk, n - 1)]))
                    for i in range(0, n, chunk)
                ]

                def run(b=b, chunks=chunks) -> None:
                    b.restart()
                    for c in chunks:
                        b(x=c)

                run()
                sps = n / median_time(run, repeats)
                rows.append(
                    {
                        "size": size,
                        "chunk": chunk,
                        "precision": precision,
                        "samples_per_s": sps,
                        "frames_per_s": 3 * sps,
                        "us_per_sample": 1e6 / sps,
                    }
                )
    return rows


def print_block(rows: list[dict]) -> None:
    print("\n(2) Ssim block, 3 sensors per sample, through __call__ (one core, median)")
    print(f"{'size':>8} {'chunk':>5} {'precision':>9} | {'samples/s':>9} {'frames/s':>9} {'µs/sample':>9}")
    for r in rows:
        print(
            f"{r['size']:>8} {r['chunk']:>5} {r['precision']:>9} | {r['samples_per_s']:9.0f} "
            f"{r['frames_per_s']:9.0f} {r['us_per_sample']:9.1f}"
        )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    ap.add_argument("--json", metavar="OUT", help="write all figures to this JSON file")
    args = ap.parse_args(argv)
    print(f"ssim bench — {platform.python_version()}, numpy {np.__version__}, one core")
    k = kernel(args.quick)
    print_kernel(k)
    b = block(args.quick)
    print_block(b)
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"kernel": k, "block": b, "quick": args.quick}, fh, indent=1)


if __name__ == "__main__":
    main()
