"""The start-up suite reads what the run prints about compiling: the two must not drift apart."""

from flowtact.bench.startup import COMPILED
from flowtact.runtime.compile_notice import CompileNotices


def test_the_suite_parses_the_supervisors_compile_lines():
    said = []
    notices = CompileNotices(said.append)
    notices.on_beat(
        "sink", "process 'sink' (nodes nlif)", False, {"compiling": "m.k", "compiled": 0, "node": "nlif"}
    )
    notices.on_ready("process 'sink' (nodes nlif)", {"compiled": 12, "compile_s": 23.75})
    notices.on_ready("process 'filter' (nodes savgol)", {"compiled": 1, "compile_s": 0.5})
    assert said[0] == (
        "process 'sink' (nodes nlif): compiling kernels for nlif (first run after an install or upgrade; "
        "numba caches them for the next runs)..."
    )
    assert [(int(n), float(s)) for n, s in COMPILED.findall("\n".join(said))] == [(12, 23.8), (1, 0.5)]


def test_compiling_after_the_start_is_told_once():
    said = []
    notices = CompileNotices(said.append)
    notices.on_beat("w", "process 'w'", False, {"compiling": "m.a", "compiled": 3, "node": "n"})
    notices.on_beat("w", "process 'w'", True, {"compiling": "m.b", "compiled": 4, "node": "n"})
    notices.on_beat("w", "process 'w'", True, {"compiling": "m.c", "compiled": 5, "node": "n"})
    late = [s for s in said if "after the start" in s]
    assert late == [
        "process 'w': compiling kernel m.b in node 'n' after the start: the run stalls meanwhile "
        "(the warm-up missed this signature; please report it)"
    ]
