"""The JupyterLab path in a real browser: notebook 07's interactive 3D view, Run All, the slider.

A JupyterLab server on loopback serves a copy of ``notebooks/07_recording_3d.ipynb`` (a copy, so
that the browser's autosave never writes outputs into the tracked notebook); headless Chromium
(Debian's ``chromium``), driven by Playwright, opens it, runs every cell through JupyterLab's own
``notebook:run-all-cells`` command, and then checks what a user sees:

* every code cell ran (an execution count) and none left an error output;
* the trame view in its iframe drew a scene (not a blank or "Loading..." canvas) with the true
  body's green in it;
* moving the frame slider to its end updates the label to the last image and redraws the view.

Marked ``slow`` and ``browser``: CI runs it after the smoke reproduction (``make test-browser``),
when notebooks 03-05 have cached the estimates the view loads. Without Chromium or Playwright it
is skipped, unless ``AIRPOSE_REQUIRE_BROWSER=1`` (set by CI), where their absence fails it.
"""
from __future__ import annotations

import io
import os
import shutil
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytestmark = [pytest.mark.slow, pytest.mark.browser]

REPO = Path(__file__).resolve().parents[2]
NOTEBOOK = REPO / "notebooks" / "07_recording_3d.ipynb"
CHROMIUM = os.environ.get("AIRPOSE_CHROMIUM", "/usr/bin/chromium")
# Chromium's own network traffic is refused on a closed machine; these flags keep it from trying.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-quic"]

_NOTEBOOK_WIDGET = "window.jupyterapp.shell.currentWidget"
_KERNEL_IDLE = f"""() => {{ const w = {_NOTEBOOK_WIDGET};
  const k = w && w.sessionContext && w.sessionContext.session && w.sessionContext.session.kernel;
  return !!k && k.status === 'idle'; }}"""
_ALL_RAN = f"""() => {{ const w = {_NOTEBOOK_WIDGET};
  if (w.sessionContext.session.kernel.status !== 'idle') return false;
  return w.content.widgets.filter(c => c.model.type === 'code').every(c => c.model.executionCount !== null); }}"""
_ERRORS = ("() => " + _NOTEBOOK_WIDGET + ".content.widgets.filter(c => c.model.type === 'code')"
           ".flatMap(c => c.model.outputs.toJSON()).filter(o => o.output_type === 'error')"
           ".map(o => o.ename + ': ' + o.evalue)")


def _browser_or_skip():
    missing = []
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
        missing.append("the Python package playwright (pip install -e '.[browser]')")
    if not Path(CHROMIUM).is_file():
        missing.append(f"Chromium at {CHROMIUM} (apt-get install chromium)")
    if missing:
        if os.environ.get("AIRPOSE_REQUIRE_BROWSER") == "1":
            pytest.fail("browser test required but missing: " + "; ".join(missing))
        pytest.skip("no browser: " + "; ".join(missing))
    return sync_playwright


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for_server(url: str, proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        if proc.poll() is not None:
            raise RuntimeError(f"jupyter lab exited with status {proc.returncode}")
        try:
            urllib.request.urlopen(url, timeout=2)
            return
        except OSError:
            time.sleep(0.5)
    raise TimeoutError(f"jupyter lab did not answer {url} within {timeout_s} s")


@pytest.fixture
def lab(tmp_path):
    """A JupyterLab server on loopback serving a copy of notebook 07; yields (base URL, token)."""
    shutil.copy(NOTEBOOK, tmp_path / NOTEBOOK.name)
    port, token = _free_port(), "airpose-browser-test"
    # The interactive view is off under CI (CI=...) and papermill (AIRPOSE_INTERACTIVE=0): a user's
    # JupyterLab has neither, so the server's kernels must not either.
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "AIRPOSE_INTERACTIVE")}
    log = open(tmp_path / "lab.log", "wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "jupyterlab", "--no-browser", "--allow-root", "--ip=127.0.0.1", f"--port={port}",
         f"--IdentityProvider.token={token}", f"--ServerApp.root_dir={tmp_path}",
         "--LabApp.expose_app_in_browser=True", "--LabApp.news_url=None",
         "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate"],
        env=env, stdout=log, stderr=subprocess.STDOUT)
    try:
        _wait_for_server(f"http://127.0.0.1:{port}/api/status?token={token}", proc)
        yield f"http://127.0.0.1:{port}", token
    finally:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()


def _image(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(np.int16)


def _green_fraction(img: np.ndarray, margin: int = 25) -> float:
    """Fraction of green-dominated pixels (the true body and its path: nothing else in the scene
    is green; shading darkens it, so hue rather than distance to one colour).

    Args:
        img: (H, W, 3) RGB image, integer values 0-255.
    """
    r, g, b = img[..., 0], img[..., 1], img[..., 2]
    return float((g - np.maximum(r, b) > margin).mean())


def _trame_frame(page, timeout_s: float = 120.0):
    """The trame view's frame, once its iframe has loaded: the widget attaches it after the last
    cell reports done, and Playwright learns of it only while it handles events (hence
    ``wait_for_timeout``, not ``time.sleep``). None if it never came."""
    t_end = time.monotonic() + timeout_s
    while time.monotonic() < t_end:
        view = next((f for f in page.frames if "index.html?ui=" in f.url), None)
        if view is not None:
            return view
        page.wait_for_timeout(500)
    return None


def test_notebook_07_runs_in_jupyterlab_and_its_3d_view_follows_the_slider(lab):
    sync_playwright = _browser_or_skip()
    base, token = lab
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 1000})
            page.goto(f"{base}/lab/tree/{NOTEBOOK.name}?token={token}")
            page.wait_for_function(f"() => window.jupyterapp !== undefined && !!{_NOTEBOOK_WIDGET}", timeout=120_000)
            page.wait_for_function(_KERNEL_IDLE, timeout=180_000, polling=500)
            page.evaluate("window.jupyterapp.commands.execute('notebook:run-all-cells')")
            page.wait_for_function(_ALL_RAN, timeout=900_000, polling=1000)
            assert page.evaluate(_ERRORS) == [], "a cell of notebook 07 raised in JupyterLab"

            # The trame view: its own page in an iframe, served by the kernel on another port.
            view = _trame_frame(page)
            assert view is not None, "no trame iframe within 120 s: the notebook fell back to static images?"
            view.wait_for_selector("canvas", state="visible", timeout=120_000)
            iframe = page.locator("iframe").first
            iframe.scroll_into_view_if_needed()
            # The view shows a spinner until its first image arrives (which has some green too).
            view.get_by_text("Loading").first.wait_for(state="hidden", timeout=120_000)
            t_end, first = time.monotonic() + 60, None
            while time.monotonic() < t_end:
                first = _image(iframe.screenshot())
                if _green_fraction(first) > 5e-4 and first.std() > 10:
                    break
                time.sleep(1)
            assert first.std() > 10, "the 3D view is blank"
            assert _green_fraction(first) > 5e-4, "the true body (green) is not in the 3D view"

            labels = page.locator(".widget-label")
            assert "image 0," in " ".join(labels.all_inner_texts())
            assert "true body and path" in " ".join(page.locator(".widget-html").all_inner_texts())  # the legend
            handle = page.locator(".noUi-handle").first
            handle.focus()
            handle.press("End")  # the slider's last frame
            page.wait_for_function(
                "() => [...document.querySelectorAll('.widget-label')].some(e => /image [1-9][0-9]*,/.test(e.textContent))",
                timeout=60_000)
            t_end, changed = time.monotonic() + 60, 0.0
            while time.monotonic() < t_end and changed < 1e-3:
                time.sleep(1)
                last = _image(iframe.screenshot())
                changed = float((np.abs(last - first).sum(-1) > 30).mean())
            assert changed >= 1e-3, "moving the slider did not redraw the 3D view"
        finally:
            browser.close()
