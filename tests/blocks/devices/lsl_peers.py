"""Plain pylsl peers for the LSL interop tests, run as separate processes (no flowtact import).

``send NAME N RATE [NAN_AT]``: an outlet of a force stream (Fx, Fy, Fz in N, float64, labels/units in its
desc); prints ``ready`` once created, waits for a consumer and then for a ``go`` line on stdin,
pushes N samples paced at RATE on the LSL clock (a device's own timing: the only waiting here is
this emulated sender's; Fx of sample NAN_AT is NaN), each stamped with ``local_clock()`` at its push, prints ``sent N FIRST
LAST`` and stays until stdin closes (the outlet must outlive the graph reading it).

``receive NAME N TIMEOUT``: resolves NAME, opens it, prints ``ready``, pulls until N samples came
or TIMEOUT passed, then prints one JSON line: the samples' values, their stamps mapped onto this
machine's LSL clock (stamp + time_correction) and their local arrival times.
"""

import json
import sys

import pylsl


def send(name: str, n: int, rate: float, nan_at: int = -1) -> None:
    info = pylsl.StreamInfo(name, "Force", 3, rate, "double64", f"peer/{name}")
    channels = info.desc().append_child("channels")
    for label in ("Fx", "Fy", "Fz"):
        ch = channels.append_child("channel")
        ch.append_child_value("label", label)
        ch.append_child_value("unit", "N")
    outlet = pylsl.StreamOutlet(info)
    print("ready", flush=True)
    if not outlet.wait_for_consumers(120.0):
        print("no consumer", flush=True)
        sys.exit(1)
    if sys.stdin.readline().strip() != "go":
        sys.exit(1)
    t0 = pylsl.local_clock()
    first = last = 0.0
    for i in range(n):
        due = t0 + i / rate
        while pylsl.local_clock() < due:  # pace like a device; a busy wait of at most 1/rate
            pass
        last = due  # stamped with its nominal time, as a device with its own clock would
        first = first or last
        fz = 0.12 + 0.02 * (i % 400 >= 200)  # a 120 mN baseline, 20 mN steps every 0.2 s
        outlet.push_sample([float("nan") if i == nan_at else 0.0, 1e-6 * i, fz], last)
    print(f"sent {n} {first!r} {last!r}", flush=True)
    sys.stdin.read()


def receive(name: str, n: int, timeout: float) -> None:
    hits = pylsl.resolve_byprop("name", name, 1, timeout)
    if not hits:
        print(json.dumps({"error": f"no stream {name}"}), flush=True)
        return
    inlet = pylsl.StreamInlet(hits[0], max_buflen=360, recover=False)  # a lost stream raises
    inlet.open_stream(timeout)
    corr = inlet.time_correction(timeout)
    info = inlet.info(timeout)
    print("ready", flush=True)
    values, stamps, arrivals = [], [], []
    deadline = pylsl.local_clock() + timeout
    lost = False
    while len(stamps) < n and pylsl.local_clock() < deadline and not lost:
        try:  # one sample as soon as it is there (pull_chunk with a timeout waits the whole timeout)
            first, t0 = inlet.pull_sample(timeout=0.05)
            x, ts = inlet.pull_chunk(timeout=0.0) if first is not None else ([], [])
            x, ts = ([first, *x], [t0, *ts]) if first is not None else (x, ts)
        except pylsl.util.LostError:  # the outlet went away: what came before is all there is
            lost, x, ts = True, [], []
        now = pylsl.local_clock()
        for row, t in zip(x, ts, strict=True):
            values.append(list(row))
            stamps.append(t + corr)
            arrivals.append(now)
    ch = info.desc().child("channels").child("channel")
    out = {
        "values": values,
        "stamps": stamps,
        "arrivals": arrivals,
        "correction": corr,
        "format": info.channel_format(),
        "rate": info.nominal_srate(),
        "label": ch.child_value("label"),
        "unit": ch.child_value("unit"),
        "kind": info.desc().child("flowtact").child_value("kind"),
        "lost": lost,
    }
    print(json.dumps(out), flush=True)


if __name__ == "__main__":
    cmd, name, a, b = sys.argv[1:5]
    if cmd == "send":
        send(name, int(a), float(b), *map(int, sys.argv[5:6]))
    else:
        receive(name, int(a), float(b))
