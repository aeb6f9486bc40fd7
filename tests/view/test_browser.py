"""``flowtact run --view`` in a real headless Chromium (Debian's chromium + chromedriver, driven
by Selenium): the page shows the chosen streams with their units, updates at least 10 times a
second, and survives the end of the run (issue 34, Done means)."""

from __future__ import annotations

import os
import queue
import re
import shutil
import subprocess
import sys
import threading
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM, CHROMEDRIVER = "/usr/bin/chromium", "/usr/bin/chromedriver"

webdriver = pytest.importorskip("selenium.webdriver")
pytest.importorskip("aiohttp")
if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):
    pytest.skip("needs Debian's chromium and chromium-driver (apt-get install chromium chromium-driver)",
                allow_module_level=True)  # fmt: skip

from selenium.webdriver.chrome.options import Options  # noqa: E402
from selenium.webdriver.chrome.service import Service  # noqa: E402
from selenium.webdriver.common.by import By  # noqa: E402
from selenium.webdriver.support.ui import WebDriverWait  # noqa: E402

HANG_S = 300  # start-up (kernel compiles) on a loaded machine; never a timing assertion


@pytest.fixture
def browser():
    o = Options()
    for a in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--window-size=1400,1000",
    ):
        o.add_argument(a)
    o.binary_location = CHROMIUM
    o.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=o)
    yield driver
    driver.quit()


class Run:
    """``flowtact run ... --view ...`` in a subprocess, its stderr read line by line."""

    def __init__(self, *args: str) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "flowtact.cli", "run", *args],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: queue.Queue[str | None] = queue.Queue()
        self.err: list[str] = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self) -> None:
        for line in self.proc.stderr:  # type: ignore[union-attr]
            self.err.append(line)
            self.lines.put(line)
        self.lines.put(None)

    def url(self) -> str:
        while (line := self.lines.get(timeout=HANG_S)) is not None:
            m = re.search(r"flowtact: view at (http://127\.0\.0\.1:\d+/\?token=\S+)", line)
            if m:
                return m.group(1)
        raise AssertionError(f"no address printed:\n{''.join(self.err)}")

    def wait(self) -> int:
        code = self.proc.wait(timeout=HANG_S)
        return code

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        self.reader.join(HANG_S)
        self.proc.stderr.close()  # type: ignore[union-attr]


CASES = {
    # graph, how it runs, streams, what each panel must say (name -> words), channel labels shown
    "touch-inproc": (
        "touch.yaml",
        ["--inproc", "--duration", "8"],
        ["sensor.force", "sa1.spikes", "sa1_stim.y", "dforce.y"],
        {"sensor.force": "3 channels, N @ 1000 Hz", "sa1.spikes": "spikes of 20 units (rates in Hz)",
         "dforce.y": "3 channels, N/s @ 1000 Hz"},
        ["Fx", "Fy", "Fz"],
    ),
    "teleop-processes": (
        "teleop.yaml",
        ["--duration", "10"],
        ["finger.f", "gripper.object", "cams.frames", "exo.angles"],
        {"finger.f": "3 channels, N @ 100 Hz", "gripper.object": "categorical: strawberry, bottle @ 100 Hz",
         "cams.frames": "frames 3×240×320 uint8, DN @ 40 Hz", "exo.angles": "9 channels, rad @ 100 Hz"},
        ["thumb", "index", "middle", "thumb φ1"],
    ),
}  # fmt: skip


@pytest.mark.slow
@pytest.mark.cli
@pytest.mark.timeout(900)
@pytest.mark.parametrize("case", sorted(CASES))
def test_the_page_shows_the_streams_updates_and_survives_the_end(case, browser):
    graph, how, streams, says, labels = CASES[case]
    run = Run(str(ROOT / "graphs" / graph), *how, "--quiet", "--view", *streams)
    try:
        browser.get(run.url())
        wait = WebDriverWait(browser, HANG_S, poll_frequency=0.1)
        frames = lambda: browser.execute_script("return window.flowtactView.frames")  # noqa: E731
        wait.until(lambda _: frames() >= 1)
        first = frames()
        wait.until(lambda _: frames() >= first + 40 or run.proc.poll() is not None)
        times = browser.execute_script("return window.flowtactView.times")[first - 1 :]
        assert len(times) >= 41, f"only {len(times)} frames while the graph ran"
        rate = (len(times) - 1) / ((times[-1] - times[0]) / 1000.0)
        assert rate >= 10.0, f"{rate:.1f} frames a second"  # the server sends 20

        panels = browser.find_elements(By.CSS_SELECTOR, "section.panel")
        assert [p.get_attribute("data-stream") for p in panels] == streams
        for p in panels:
            name = p.get_attribute("data-stream")
            assert p.find_element(By.TAG_NAME, "h2").text == name
            if name in says:
                assert p.find_element(By.CLASS_NAME, "what").text == says[name]
        text = browser.find_element(By.TAG_NAME, "main").text
        assert all(lab in text for lab in labels), text  # the channel labels, in the legends
        if "cams.frames" in streams:
            cap = browser.find_element(By.CSS_SELECTOR, "[data-stream='cams.frames'] .axis").text
            assert re.search(r"3 tiles of \d+×\d+ px shown, values [\d.]+–[\d.]+ DN", cap), cap
        if "gripper.object" in streams:
            current = browser.find_element(By.CSS_SELECTOR, "[data-stream='gripper.object'] .current").text
            assert current in ("strawberry", "bottle")
        if "sa1.spikes" in streams:
            cap = browser.find_element(By.CSS_SELECTOR, "[data-stream='sa1.spikes'] .axis").text
            assert "rate per unit (Hz)" in cap

        assert run.wait() == 0, "".join(run.err)
        wait.until(lambda _: browser.execute_script("return window.flowtactView.ended"))
        status = browser.find_element(By.ID, "status").text
        assert status == "the run ended (the last data stays shown)"
        assert len(browser.find_elements(By.CSS_SELECTOR, "section.panel canvas")) >= len(streams)
        if shot := os.environ.get("FLOWTACT_VIEW_SCREENSHOT"):  # docs/view.png (docs/view.md)
            browser.save_screenshot(shot.replace("{case}", case))
        severe = [e for e in browser.get_log("browser") if e["level"] == "SEVERE"]
        assert not severe, severe
        err = "".join(run.err)
        assert not re.search(r"Traceback|Task was destroyed|Exception|Error", err), err
    finally:
        run.kill()
