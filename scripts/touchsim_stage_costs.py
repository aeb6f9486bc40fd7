"""CPU time of each stage of a whole hand's afferents: the synthetic stimulus (touchsim_probe),
TouchSim's prefilter (iir), current (rectified_gain) and membranes (nlif, graphs/hand.yaml's
models), and the whole model fused in one block (touchsim_chain, what graphs/hand.yaml runs),
17 000 channels at 5 kHz in 50-sample chunks (10 ms ticks), noise and saturation on; median of 40
chunks.

    python scripts/touchsim_stage_costs.py

Prints milliseconds of CPU per 10 ms of signal (< 10: faster than real time on one core) and the
load average (other processes slow it through shared caches).
"""

from __future__ import annotations

import os
import time

import numpy as np

from flowtact import Chunk, StreamSpec
from flowtact.blocks.signal.iir import Iir
from flowtact.blocks.signal.rectified_gain import RectifiedGain
from flowtact.blocks.spiking.nlif import Nlif
from flowtact.blocks.touch.hand import hand_models
from flowtact.blocks.touch.touchsim_chain import TouchsimChain
from flowtact.blocks.touch.touchsim_probe import TouchsimProbe

N, FS, CHUNK = 17_000, 5000.0, 50


def main() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(CHUNK, N))
    spec = StreamSpec(dtype="float64", shape=(N,), rate_hz=FS)
    iir = Iir(cutoff_hz=list(rng.uniform(70, 370, N)))
    iir.bind({"x": spec})
    gains = RectifiedGain(
        pos1=[0.4], neg1=[0.3], pos2=[0.3], neg2=[0.2], ahead="x2", ahead_pos=[1.0], ahead_neg=[2.0],
        noise_sd=[0.05], saturation=[10.0],
    )  # fmt: skip
    gains.bind({"x1": spec, "x2": spec})

    def cost(step) -> float:  # type: ignore[no-untyped-def]
        times = []
        for k in range(40):
            c = Chunk((np.arange(CHUNK) + k * CHUNK) / FS, x)
            t0 = time.process_time()
            step(c)
            times.append(time.process_time() - t0)
        return float(np.median(times[1:]))  # the first call may compile

    a, b = cost(lambda c: iir(x=c)), cost(lambda c: gains(x1=c, x2=c))
    probe = TouchsimProbe(n=N, repeat=True)
    probe.bind({})
    p = cost(lambda c: probe(float(c.t[-1]) + 1.0 / FS))
    neurons = Nlif(models=[hand_models()[i % len(hand_models())] for i in range(N)])
    neurons.bind({"x": spec})
    drive = 0.02 * x  # TouchSim-sized currents: the afferents fire now and then
    m = cost(lambda c: neurons(x=Chunk(c.t, drive)))
    fused = TouchsimChain(models=list(neurons.config.models))
    fused.bind({"s": spec, "d": spec})
    s_in = np.abs(x) * 0.01
    f = cost(lambda c: fused(s=Chunk(c.t, s_in), d=c))
    per = 1e3 * CHUNK / FS
    print(f"N={N:,} at {FS:g} Hz, {CHUNK}-sample chunks: CPU ms per {per:g} ms of signal")
    print(f"  iir (butter 3, per-channel cut-offs): {a * 1e3:.1f}")
    print(f"  rectified_gain (s, d, ahead Δd, noise, saturation): {b * 1e3:.1f}")
    print(f"  touchsim_probe (synthetic s and d): {p * 1e3:.1f}")
    print(f"  nlif (the hand's TouchSim models, last-spike history): {m * 1e3:.1f}")
    print(f"  a hand's chain (probe, 2 iir, rectified_gain, nlif): {(p + 2 * a + b + m) * 1e3:.1f}")
    print(f"  touchsim_chain (the same model fused, one block): {f * 1e3:.1f}")
    print(f"  a hand's fused chain (probe, touchsim_chain): {(p + f) * 1e3:.1f}")
    print(f"  load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
