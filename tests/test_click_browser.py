"""The click demo in a real browser: headless Chromium (Debian's, driven by playwright) opens the viser page, clicks
the floor, and the server must take that goal and rebuild HumanoidPF for it (F_H at the root turns to it)."""

from __future__ import annotations

import shutil
import socket
import time

import numpy as np
import pytest

playwright_sync = pytest.importorskip("playwright.sync_api", reason="playwright not installed (pip install -e .[dev])")

CHROMIUM_ARGS = ["--no-sandbox", "--disable-dev-shm-usage", "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]


def _chromium_path() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    return None


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait(predicate, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")


def _root_direction(rt) -> np.ndarray:
    f = rt.view().f_h[0, :2]
    return f / max(np.linalg.norm(f), 1e-9)


def _toward(rt, goal) -> np.ndarray:
    d = np.asarray(goal[:2]) - rt.view().qpos[:2]
    return d / np.linalg.norm(d)


@pytest.fixture()
def chromium_browser():
    path = _chromium_path()
    if path is None:
        pytest.skip("Chromium cannot start: no chromium executable (apt-get install chromium)")
    pw = playwright_sync.sync_playwright().start()
    try:
        b = pw.chromium.launch(executable_path=path, headless=True, args=CHROMIUM_ARGS)
    except Exception as err:  # missing libraries, sandbox trouble, ...
        pw.stop()
        pytest.skip(f"Chromium cannot start: {str(err).splitlines()[0]}")
    yield b
    b.close()
    pw.stop()


def test_click_sets_goal_and_rebuilds_field(chromium_browser):
    from cat.deploy.cli import ClickCfg, build_runtime
    from cat.deploy.viewer import ClickApp, ViewerCfg

    rt = build_runtime(ClickCfg(scene="flat", checkpoint="hold"))
    app = ClickApp(rt, ViewerCfg(port=_free_port()))
    app.start()
    try:
        # a first goal behind the robot: F_H at the root points back (-x)
        first = rt.set_goal((-1.5, 0.0))
        _wait(lambda: rt.used_field is not None and rt.used_field.goal_version == rt.goal_version, 60, "first field")
        assert _root_direction(rt) @ _toward(rt, first) > 0.9

        page = chromium_browser.new_page(viewport={"width": 1280, "height": 720})
        page.goto(app.url)
        page.get_by_text("Click the floor").wait_for(timeout=60_000)  # GUI synced: the client is connected
        _wait(lambda: len(app.server.get_clients()) > 0, 30, "the viser client")
        time.sleep(2.0)  # initial camera and scene applied
        # the initial camera looks at (start.x + 1, start.y, 0): the canvas centre is that floor point
        page.mouse.click(640, 360)
        # wait for the handler to finish (it sets last_click after the runtime took the goal: no race on it)
        _wait(lambda: app.last_click is not None, 30, "the click to reach the server")
        goal = app.last_click.copy()
        assert np.allclose(rt.goal, goal)
        assert np.linalg.norm(goal[:2] - (rt.scene.start[:2] + [1.0, 0.0])) < 0.3, goal
        _wait(lambda: rt.used_field is not None and rt.used_field.goal_version == rt.goal_version, 60, "new field")
        assert np.allclose(rt.used_field.goal, goal)
        # F_H at the root turned from the old goal (behind) to the clicked one (ahead)
        assert _root_direction(rt) @ _toward(rt, goal) > 0.9
        assert "Goal set to" in page.content() or app.message.startswith("Goal set to")
    finally:
        app.stop()
