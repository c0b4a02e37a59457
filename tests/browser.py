"""A test helper: screenshots of Meshcat pages in a real headless browser.

The browser is Chromium or Chrome (`find_browser`), run once per picture as
`--headless=new --screenshot` with software WebGL (SwiftShader), a private
throw-away profile and a virtual clock: `--virtual-time-budget` lets the
page run for that much page time, advancing the clock only while the page
is idle, so a picture does not depend on the machine's speed. Each run has
a timeout, after which the browser's whole process group is killed.

Two moments of a replay. A page from `drake_wbc.experiments.replay` plays its
animation once as soon as it has loaded (Drake's default autoplay), and the
virtual clock drives it: pictures after 300 and 1800 ms of page time show
the robot at two places. Which two, though, depends on when in page time
the animation started, after the page's scene commands (data URLs) were
fetched and decoded, and a run that ends before the budget would clamp
both at its last frame. So instead `seek_copy` writes a copy of the page
with one added script that waits until the animation is loaded, pauses it
and seeks it to the wanted time: what the page's own time slider (Open
Controls > Animations > time) does, through the same `viewer.animator`.
The moment shown is then exactly the one asked for, whatever the loading
took. The script reports what it did in a hidden element; `screenshot`
also dumps the final DOM (`--dump-dom`, in the same run) and returns that
report, so a test can tell "the animation never loaded" from "the robot
did not move". The copy differs from the page only by that script, and
tests/test_replay_page.py also screenshots the page exactly as written, to
check that it draws the robot by itself.

Pictures are read with matplotlib (a dependency of the project) as float
arrays in [0, 1]; the measures below compare them with each other and with
a picture of an empty Meshcat scene, which has the same background, grid
and camera.
"""

import html
import os
import re
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import matplotlib.image
import numpy as np

BROWSER_NAMES = ("chromium", "chromium-browser", "google-chrome",
                 "google-chrome-stable")
"""The programs looked for on PATH, in this order."""

BROWSER_FLAGS = (
    # The new headless mode (the only one since Chrome 132) writes both the
    # screenshot and the DOM in one run; the old one did only one of them.
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--use-gl=swiftshader",
    "--enable-unsafe-swiftshader",
    "--hide-scrollbars",
    "--mute-audio",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-extensions",
    "--disable-background-networking",
)
"""Headless, software rendering, nothing that reaches the network."""

STATUS_ID = "replay-test-status"
"""The id of the element in which the seek script reports."""

_SEEK_SCRIPT = """
<script>
// Added for a test: pause the recorded animation at a chosen time.
(function () {
  const target = %(time)r;
  let waited = 0;
  function report(text) {
    let status = document.getElementById(%(status_id)r);
    if (!status) {
      status = document.createElement("pre");
      status.id = %(status_id)r;
      status.style.display = "none";
      document.body.appendChild(status);
    }
    status.textContent = text;
  }
  function seek() {
    const animator = typeof viewer === "undefined" ? null : viewer.animator;
    if (animator && animator.actions.length > 0) {
      animator.pause();
      animator.seek(target);
      report("seeked " + target + " of " + animator.duration + " s, " +
             animator.actions.length + " animated objects");
      return;
    }
    waited += 50;
    report("no animation after " + waited + " ms");
    if (waited < %(wait_ms)d) {
      setTimeout(seek, 50);
    }
  }
  seek();
})();
</script>
"""


class BrowserError(RuntimeError):
    """The browser failed, timed out, or wrote no picture."""


def find_browser():
    """Returns (path, None) for a working browser, else (None, reason).

    A program counts as working when `PROGRAM --version` succeeds within
    20 s (e.g. Ubuntu's chromium-browser without its snap does not).
    """
    tried = []
    for name in BROWSER_NAMES:
        path = shutil.which(name)
        if path is None:
            continue
        try:
            result = subprocess.run(
                [path, "--version"], capture_output=True, text=True,
                timeout=20, check=False,
            )
        except (OSError, subprocess.TimeoutExpired) as error:
            tried.append(f"{path} ({error})")
            continue
        if result.returncode == 0 and result.stdout.strip():
            return path, None
        tried.append(f"{path} (--version exited {result.returncode})")
    if tried:
        return None, "no working browser: " + "; ".join(tried)
    return None, (
        "no browser on PATH (looked for " + ", ".join(BROWSER_NAMES) + "); "
        "install one, e.g. `apt-get install chromium`"
    )


def seek_copy(page, copy, time):
    """Writes to `copy` the page `page` with its animation held at `time`.

    Args:
        page: a Meshcat HTML page with a published animation.
        copy: the file to write.
        time: the replay time to show, s.

    Returns:
        pathlib.Path: `copy`.
    """
    text = Path(page).read_text(encoding="utf-8")
    end = text.rfind("</body>")
    if end < 0:
        raise ValueError(f"{page} has no </body>: not a Meshcat page")
    script = _SEEK_SCRIPT % {
        "time": float(time), "status_id": STATUS_ID, "wait_ms": 20000,
    }
    copy = Path(copy)
    copy.write_text(text[:end] + script + text[end:], encoding="utf-8")
    return copy


def screenshot(browser, page, png, size=(800, 600), budget_ms=2000,
               timeout=90.0, attempts=2):
    """Opens `page` in `browser`, lets it run, saves a screenshot; a run
    that times out (a loaded machine can stall headless chromium's virtual
    clock) is tried again once with a fresh profile.

    Args:
        browser: the browser's program (see `find_browser`).
        page: the HTML file to open.
        png: the PNG file to write.
        size: (width, height) of the window in pixels.
        budget_ms: the page time the page runs for before the picture.
        timeout: the wall-clock limit of each of the browser's runs, s.
        attempts: how many runs before a timeout is an error.

    Returns:
        str or None: the report of a `seek_copy` script, None if the page
        has none.

    Raises:
        BrowserError: when the browser fails, times out (it is then
            killed, with every process it started) or writes no picture.
    """
    for attempt in range(attempts):
        try:
            return _screenshot_once(browser, page, png, size, budget_ms,
                                    timeout)
        except BrowserTimeoutError:
            if attempt == attempts - 1:
                raise


class BrowserTimeoutError(BrowserError):
    """The browser did not finish within its time limit."""


def _screenshot_once(browser, page, png, size, budget_ms, timeout):
    png = Path(png)
    png.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory(prefix="replay-browser-") as profile:
        command = [
            browser, *BROWSER_FLAGS,
            f"--user-data-dir={profile}",
            f"--window-size={size[0]},{size[1]}",
            f"--virtual-time-budget={int(budget_ms)}",
            f"--screenshot={png}",
            "--dump-dom",
            Path(page).resolve().as_uri(),
        ]
        process = subprocess.Popen(
            command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True, errors="replace", start_new_session=True,
        )
        try:
            dom, errors = process.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_group(process)
            raise BrowserTimeoutError(
                f"{browser} did not finish {page} within {timeout} s and "
                "was killed"
            ) from None
        except BaseException:
            _kill_group(process)
            raise
    if process.returncode != 0 or not png.is_file():
        tail = "\n".join(errors.strip().splitlines()[-15:])
        raise BrowserError(
            f"{browser} exited {process.returncode} without a screenshot "
            f"of {page}; the end of its error output:\n{tail}"
        )
    match = re.search(
        rf'<pre id="{STATUS_ID}"[^>]*>(.*?)</pre>', dom, re.DOTALL
    )
    return html.unescape(match.group(1)) if match else None


def _kill_group(process):
    """Kills the browser's process group (it was started as its leader)."""
    try:
        os.killpg(process.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    process.communicate()


def read_png(path):
    """Returns the RGB channels of a PNG as a float array in [0, 1]."""
    image = np.asarray(matplotlib.image.imread(str(path)), dtype=float)
    if image.ndim != 3 or image.shape[2] < 3:
        raise ValueError(f"{path} is not an RGB picture: {image.shape}")
    if image.max() > 1.0:
        image = image / 255.0
    return image[..., :3]


def distinct_colours(image):
    """Returns the number of distinct 8-bit RGB colours in `image`."""
    q = np.round(image * 255).astype(np.int64)
    return len(np.unique((q[..., 0] << 16) | (q[..., 1] << 8) | q[..., 2]))


def difference_mask(a, b, threshold=0.15):
    """Returns the boolean mask of the pixels where pictures `a` and `b`
    differ by more than `threshold` in some channel."""
    if a.shape != b.shape:
        raise ValueError(f"pictures differ in size: {a.shape}, {b.shape}")
    return np.abs(a - b).max(axis=2) > threshold


def mask_centroid(mask):
    """Returns (column, row), the mean position of the mask's pixels."""
    rows, columns = np.nonzero(mask)
    return np.array([columns.mean(), rows.mean()])
