"""Test helper: the real rerun viewer, headless (`rerun --headless`: no OS window, no X server; Mesa's
software Vulkan, Debian mesa-vulkan-drivers, which `make chromium` installs), driven through rerun's own
control API (`rerun.experimental.ViewerClient`): open a .rrd, wait until it has loaded, read what each
view reports, screenshot the whole window or one view.  Skips, saying what is missing, where there is no
Vulkan driver or no viewer binary.

Colours are judged by hue, as a person names them (`hue_masks`): the calibrated robot's body is blue,
the nominal robot red (seen through the translucent blue body it turns pink-red, still red by hue)."""

from __future__ import annotations

import glob
import io
import socket
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

WINDOW = "1600x1000"


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _png(data: bytes) -> np.ndarray:
    from matplotlib.image import imread

    return imread(io.BytesIO(data), format="png")[..., :3]


class Viewer:
    """One headless viewer process showing one .rrd (a context manager).  `views` → {name: View}
    (rerun's `View`: view_id, view_class, name, reports); `screenshot(name=None)` → (h, w, 3) floats 0…1
    of the whole window or of the view called `name`."""

    def __init__(self, rrd: Path, timeout_s: float = 180.0):
        self.rrd, self.timeout_s = Path(rrd), timeout_s

    def __enter__(self) -> Viewer:
        from rerun.experimental import ViewerClient

        try:
            import rerun_cli
            exe = Path(rerun_cli.__file__).with_name("rerun")
        except ImportError:
            exe = None
        if exe is None or not exe.is_file():
            pytest.skip("the rerun viewer binary (rerun-cli, installed with rerun-sdk) is not here")
        if not glob.glob("/usr/share/vulkan/icd.d/*.json"):
            pytest.skip("no Vulkan driver for the viewer (apt-get install mesa-vulkan-drivers, or `make chromium`)")
        port = _free_port()
        self.proc = subprocess.Popen([str(exe), "--headless", "--port", str(port), "--window-size", WINDOW,
                                      "--hide-welcome-screen"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        deadline = time.monotonic() + self.timeout_s
        while True:
            try:
                self.client = ViewerClient.connect(f"rerun+http://127.0.0.1:{port}/proxy")
                self.client.get_state()
                break
            except Exception:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    self.__exit__(None, None, None)
                    raise AssertionError(f"the headless viewer did not start: {self._stderr()}") from None
                time.sleep(0.2)
        self.client.open(str(self.rrd.resolve()))
        while (st := self.client.get_state()).loading or not st.views:
            assert time.monotonic() < deadline, f"{self.rrd} still loading after {self.timeout_s} s: {st.loading}"
            time.sleep(0.2)
        rec = next(r for r in st.recordings if r.store_id == st.active_recording)
        if rec.current_timeline:  # paused at the start, as a user opening the file sees it first
            tl = next(t for t in rec.timelines if t.name == rec.current_timeline)
            kind = {"timestamp": "timestamp", "duration": "duration"}.get(tl.time_type, "sequence")
            self.client.set_time(tl.name, **{kind: np.datetime64(tl.start, "ns") if kind == "timestamp" else tl.start},
                                 play_state="paused")
        return self

    def _stderr(self) -> str:
        if self.proc.poll() is None:
            return ""
        return self.proc.stderr.read().decode(errors="replace")[-2000:]

    def __exit__(self, *exc) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc.stderr.close()

    @property
    def views(self) -> dict:
        return {v.name: v for v in self.client.get_state().views}

    def screenshot(self, name: str | None = None) -> np.ndarray:
        """The whole window, or view `name`, once two consecutive frames agree (the chunks a view
        draws arrive on demand: the first frame after loading may still miss some)."""
        view = None if name is None else self.views[name].view_id
        last = None
        for _ in range(10):
            img = _png(self.client.take_screenshot(view))
            if last is not None and img.shape == last.shape and np.array_equal(img, last):
                return img
            last = img
            time.sleep(0.3)
        return last


def viewer_screenshot(rrd: Path, shot: Path) -> np.ndarray:
    """The viewer's 1600×1000 window showing `rrd`, as an (h, w, 3) float image in 0…1 (also saved to `shot`)."""
    from matplotlib.image import imsave

    with Viewer(rrd) as v:
        img = v.screenshot()
    imsave(shot, img)
    return img


def hue_masks(img: np.ndarray) -> dict[str, np.ndarray]:
    """Pixels a person would call blue (hue 200–250°) and red (hue ≥ 310° or ≤ 20°, pink-red included),
    saturated (≥ 0.4) and not dark (value ≥ 0.3)."""
    from matplotlib.colors import rgb_to_hsv

    hsv = rgb_to_hsv(np.clip(img, 0, 1))
    hue, vivid = hsv[..., 0] * 360, (hsv[..., 1] >= 0.4) & (hsv[..., 2] >= 0.3)
    return {"blue": vivid & (hue >= 200) & (hue <= 250), "red": vivid & ((hue >= 310) | (hue <= 20))}


def robot_in_view(img: np.ndarray) -> dict:
    """What a person sees of the two robots in a 3-D view's screenshot: the calibrated robot's body — the
    largest connected blue region — and the nominal robot's red inside it (within 1 % of the view's size of
    the body).  Returns the body's share of the view, its extent (fractions of the view's height and width),
    the share of the blue pixels it holds, the red pixels inside the body, their extent as fractions of the
    body's, and the blue and red pixel counts within the body's bounding box."""
    from scipy import ndimage

    m = hue_masks(img)
    h, w = img.shape[:2]
    lab, n = ndimage.label(m["blue"])
    if n == 0:
        return {"body_share": 0.0, "body_extent": (0.0, 0.0), "red_inside": 0, "red_extent": (0.0, 0.0),
                "blue_in_box": 0, "red_in_box": 0, "body_of_blue": 0.0}
    sizes = ndimage.sum(m["blue"], lab, range(1, n + 1))
    body = lab == (int(np.argmax(sizes)) + 1)
    ys, xs = np.nonzero(body)
    ext = ((ys.max() - ys.min() + 1) / h, (xs.max() - xs.min() + 1) / w)
    near = ndimage.binary_dilation(body, iterations=max(1, int(0.01 * max(h, w))))
    inside = m["red"] & near
    ry, rx = np.nonzero(inside)
    red_ext = (0.0, 0.0) if len(ry) == 0 else (((ry.max() - ry.min() + 1) / h) / ext[0],
                                               ((rx.max() - rx.min() + 1) / w) / ext[1])
    box = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
    return {"body_share": float(body.mean()), "body_extent": ext, "body_of_blue": float(sizes.max() / m["blue"].sum()),
            "red_inside": int(inside.sum()), "red_extent": red_ext,
            "blue_in_box": int(m["blue"][box].sum()), "red_in_box": int(m["red"][box].sum())}
