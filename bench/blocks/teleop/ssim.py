"""Suite ``ssim``: the SSIM kernel and block in frames/s on one core, against scikit-image.

(1) Kernel: mean SSIM of one uint8 frame against a fixed reference for the thesis's cropped 90×240
    frames and full 240×320 frames: flowtact float64 (the default), flowtact float32, and
    scikit-image's ``structural_similarity(win_size=7, gaussian_weights=False, data_range=255)`` —
    the oracle, the baseline measured in the same run. Frames: emulated TacTip images
    (``tactip_sim``'s renderer) at 8 contact forces, as in ../shared/NUMERICS.md §2. flowtact is
    timed batched (all frames in one kernel call) and one frame per call. Also the largest
    |flowtact − skimage| and issue 4's bars (float64: ≥ 5 000 frames/s at 90×240, ≥ 1 500 at 240×320).
(2) Block: samples/s through ``Ssim.__call__`` with 3 sensors per sample, one sample per chunk
    (a live 40 Hz graph) and 40 per chunk; frames/s = 3 × samples/s.
"""

from __future__ import annotations

import numpy as np

from flowtact import Chunk, StreamSpec
from flowtact.benchmark import Context, Suite
from flowtact.blocks.teleop.image import centre_crop
from flowtact.blocks.teleop.ssim import Ssim, SsimReference
from flowtact.blocks.teleop.tactip_sim import pressed_frames

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
    from skimage.metrics import structural_similarity  # the baseline (dev extra)

    return structural_similarity(ref, cur, win_size=7, gaussian_weights=False, data_range=255)


# -- (1) kernel ---------------------------------------------------------------------------------------


def kernel(ctx: Context) -> None:
    for size in SIZES:
        ref, frames = tactip_frames(size)
        want = np.array([skimage_ssim(ref, f) for f in frames])
        batch = np.ascontiguousarray(np.tile(frames, (4 if ctx.quick else 16, 1, 1))[:, None])
        n_sk = len(frames) * (1 if ctx.quick else 2)

        def run_skimage(frames=frames, ref=ref, n_sk=n_sk) -> None:
            for i in range(n_sk):
                skimage_ssim(ref, frames[i % len(frames)])

        base = f"scikit-image, {size}"
        ctx.speed(base, run_skimage, n_sk, "frames/s", is_baseline=True, repeats=max(3, ctx.repeats // 3))
        for precision in ("float64", "float32"):
            r = SsimReference(ref[None], precision)
            got = r.compare(frames[:, None])[:, 0]
            err = float(np.max(np.abs(got - want)))
            ctx.figure(f"max |flowtact - skimage|, {precision}, {size}", err, "1", "lower")
            fig = ctx.speed(f"kernel {precision} batched, {size}", lambda r=r, b=batch: r.compare(b), len(batch),
                            "frames/s", baseline=base, params={"size": size, "precision": precision})  # fmt: skip
            singles = [batch[i : i + 1] for i in range(len(batch))]

            def one_by_one(r=r, singles=singles) -> None:
                for s in singles:
                    r.compare(s)

            ctx.speed(f"kernel {precision} one per call, {size}", one_by_one, len(batch), "frames/s",
                      baseline=base, params={"size": size, "precision": precision})  # fmt: skip
            if precision == "float64":
                ctx.check(f"{size} float64 >= {BARS_FPS[size]:.0f} frames/s (issue 4)", fig.median >= BARS_FPS[size],
                          f"{fig.median:.0f} frames/s")  # fmt: skip


# -- (2) block ----------------------------------------------------------------------------------------


def block(ctx: Context) -> None:
    for size, (h, w) in SIZES.items():
        ref, frames = tactip_frames(size, seed=1)
        stacks = np.stack([np.stack([f, f[::-1], f[:, ::-1]]) for f in frames])  # (8, 3, H, W)
        n = 40 if ctx.quick else 160
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

                ctx.speed(f"block {precision}, 3 sensors, chunk {chunk}, {size}", run, 3 * n, "frames/s",
                          baseline=f"scikit-image, {size}", params={"size": size, "chunk": chunk})  # fmt: skip


def run(ctx: Context) -> None:
    kernel(ctx)
    block(ctx)


SUITE = Suite(
    name="ssim",
    title="SSIM kernel and block: frames/s on one core",
    measures="Mean SSIM (7×7 box window) of emulated TacTip frames against a fixed reference, frames/s "
    "on one core at 90×240 and 240×320, float64 and float32, batched and one frame per call; the `ssim` "
    "block with 3 sensors per sample; and the largest difference from scikit-image.",
    baseline="scikit-image `structural_similarity(win_size=7, gaussian_weights=False, data_range=255)` "
    "on the same frames",
    run=run,
    needs=("skimage",),
    minutes_quick=0.3,
    minutes_full=1.0,
)
