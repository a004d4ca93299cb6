"""The browser view (viser): scene, the G1 (its visual meshes, ``cat.deploy.robot_mesh``; its collision geoms when
the model has none), goal, F_H arrows, the robot's map window; a click on the floor sends the robot there.

Three threads: the runtime's control loop (50 Hz, real time), perception (10 Hz, in the runtime), and the
render loop here (``render_hz``, default 30 Hz), which copies the robot's state under the runtime's lock and
pushes it to the browser in one atomic update.
"""

from __future__ import annotations

import contextlib
import io
import logging
import threading
import time
from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh
import viser

from cat.deploy.perception import occupied_in_map
from cat.deploy.robot_mesh import visual_meshes
from cat.deploy.runtime import Runtime
from cat.deploy.scenes import GoalError, floor_hit

log = logging.getLogger(__name__)

ROBOT_RGB = (120, 170, 230)
ARROW_RGB = (40, 200, 90)
MAP_RGB = (230, 150, 40)
HELP = "**Click the floor** to send the G1 there."


@dataclass
class ViewerCfg:
    host: str = "127.0.0.1"
    port: int = 8080
    render_hz: float = 30.0
    arrow_scale: float = 0.4  # metres of arrow per unit of F_H
    robot_meshes: bool = True  # the G1's visual meshes (else its collision capsules)
    mesh_keep: float = 0.1  # fraction of the visual meshes' triangles drawn (decimated once, cached)


def _geom_mesh(model: mujoco.MjModel, g: int) -> trimesh.Trimesh:
    """A trimesh of one capsule / sphere / box geom in its own frame."""
    t, size = model.geom_type[g], model.geom_size[g]
    if t == mujoco.mjtGeom.mjGEOM_CAPSULE:
        return trimesh.creation.capsule(height=2 * size[1], radius=size[0], count=[12, 12])
    if t == mujoco.mjtGeom.mjGEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=size[0])
    if t == mujoco.mjtGeom.mjGEOM_BOX:
        return trimesh.creation.box(extents=2 * size[:3])
    if t == mujoco.mjtGeom.mjGEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=size[0], height=2 * size[1])
    raise ValueError(f"geom {model.geom(g).name!r}: type {int(t)} not drawable")


def _box_edges(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(12, 2, 3) edges of an axis-aligned box."""
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    pairs = [(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6), (3, 7)]
    return np.stack([[c[a], c[b]] for a, b in pairs])


class ClickApp:
    """viser server around a ``Runtime``; ``start`` launches the robot and the render loop."""

    def __init__(self, runtime: Runtime, cfg: ViewerCfg | None = None):
        self.rt = runtime
        self.cfg = cfg or ViewerCfg()
        with contextlib.redirect_stdout(io.StringIO()):  # viser prints a URL panel of its own; we print one line
            self.server = viser.ViserServer(host=self.cfg.host, port=self.cfg.port, verbose=False)
        self.message = ""
        self.last_click: np.ndarray | None = None
        self.clicks = 0
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._shown_field = None
        self._build_scene()
        self._build_gui()
        self._register_click()

    @property
    def url(self) -> str:
        return f"http://{self.cfg.host}:{self.server.get_port()}"

    # --- scene ----------------------------------------------------------------------------------------------
    def _build_scene(self) -> None:
        sc, rt = self.server.scene, self.rt
        sc.set_up_direction("+z")
        b = rt.scene.bounds
        centre = (b[0] + b[1]) / 2
        size = b[1] - b[0]
        sc.add_grid("/floor", width=float(size[0]), height=float(size[1]), position=(centre[0], centre[1], 0.0))
        if len(rt.scene.mesh.faces):
            mesh = rt.scene.mesh.copy()
            mesh.visual = trimesh.visual.ColorVisuals(mesh, face_colors=(190, 140, 90, 255))
            sc.add_mesh_trimesh("/scene", mesh)
        view = rt.view()
        self._robot, self._bodies = [], []
        meshes = visual_meshes(rt.robot, self.cfg.mesh_keep) if self.cfg.robot_meshes else []
        for bm in meshes:
            b = mujoco.mj_name2id(rt.model, mujoco.mjtObj.mjOBJ_BODY, bm.body)
            if b < 0:
                continue
            handle = sc.add_mesh_simple(
                f"/robot/{bm.body}",
                bm.mesh.vertices.astype(np.float32),
                bm.mesh.faces.astype(np.uint32),
                color=ROBOT_RGB,
                position=tuple(view.body_pos[b]),
                wxyz=tuple(view.body_quat[b]),
            )
            self._bodies.append((handle, b))
        if not self._bodies:  # no visual meshes: one batched mesh per distinct collision (type, size)
            self._add_collision_geoms(view)
        self._goal = sc.add_icosphere("/goal", radius=0.07, color=(240, 60, 60), visible=False)
        self._goal_pole = sc.add_line_segments(
            "/goal_pole", np.zeros((1, 2, 3)), colors=(240, 60, 60), thickness=0.01, visible=False
        )
        self._arrows = sc.add_arrows(
            "/field/F_H",
            self._arrow_points(view),
            colors=ARROW_RGB,
            shaft_radius=0.008,
            head_radius=0.02,
            head_length=0.04,
            visible=False,
        )
        self._window = sc.add_line_segments("/map/window", np.zeros((12, 2, 3)), colors=(120, 120, 255), visible=False)
        self._occupied = sc.add_point_cloud(
            "/map/occupied", np.zeros((1, 3)), colors=MAP_RGB, point_size=0.03, visible=False
        )
        cam = self.server.initial_camera
        start = rt.scene.start
        cam.position = (float(start[0] - 1.2), float(start[1] - 2.4), 2.2)
        cam.look_at = (float(start[0] + 1.0), float(start[1]), 0.0)
        cam.up = (0.0, 0.0, 1.0)

    def _add_collision_geoms(self, view) -> None:
        rt, sc = self.rt, self.server.scene
        groups: dict[tuple, list[int]] = {}
        for k, g in enumerate(rt.geom_ids):
            key = (int(rt.model.geom_type[g]), *np.round(rt.model.geom_size[g], 5).tolist())
            groups.setdefault(key, []).append(k)
        for n, idx in enumerate(groups.values()):
            m = _geom_mesh(rt.model, rt.geom_ids[idx[0]])
            handle = sc.add_batched_meshes_simple(
                f"/robot/g{n}",
                m.vertices,
                m.faces,
                batched_wxyzs=view.geom_quat[idx],
                batched_positions=view.geom_pos[idx],
                batched_colors=ROBOT_RGB,
            )
            self._robot.append((handle, np.array(idx)))

    def _arrow_points(self, view) -> np.ndarray:
        f_h = view.f_h * self.cfg.arrow_scale
        f_h = np.where(np.linalg.norm(f_h, axis=1, keepdims=True) < 1e-4, [0.0, 0.0, 1e-4], f_h)
        return np.stack((view.link_pos, view.link_pos + f_h), axis=1)

    def _build_gui(self) -> None:
        gui = self.server.gui
        gui.add_markdown(HELP)
        self._status = gui.add_markdown("Robot standing: no goal yet.")
        self._message_md = gui.add_markdown(" ")
        reset = gui.add_button("Reset robot")
        reset.on_click(lambda _: self.rt.reset())

    def _register_click(self) -> None:
        scene = self.server.scene
        if hasattr(scene, "on_click"):  # viser >= 1.1
            scene.on_click()(self._handle_click)
        else:
            scene.on_pointer_event(event_type="click")(self._handle_click)

    # --- clicks ---------------------------------------------------------------------------------------------
    def _handle_click(self, event) -> None:
        xy = floor_hit(event.ray_origin, event.ray_direction)
        self.clicks += 1
        if xy is None:
            self._notify(event, "Click the floor, not the sky.")
            return
        try:
            goal = self.rt.set_goal(xy)
        except GoalError as err:
            self._notify(event, f"{err}; keeping the previous goal.")
            return
        self.last_click = goal
        self._show_message(f"Goal set to ({goal[0]:.2f}, {goal[1]:.2f}).")

    def _notify(self, event, text: str) -> None:
        log.info("click rejected: %s", text)
        self._show_message(text)
        client = getattr(event, "client", None)
        if client is not None:
            client.add_notification("Goal not accepted", text, auto_close_seconds=5.0, color="red")

    def _show_message(self, text: str) -> None:
        self.message = text
        self._message_md.content = text

    # --- render loop ----------------------------------------------------------------------------------------
    def render_once(self) -> None:
        view = self.rt.view()
        live = self.rt.perception.latest
        with self.server.atomic():
            for handle, idx in self._robot:
                handle.batched_positions = view.geom_pos[idx]
                handle.batched_wxyzs = view.geom_quat[idx]
            for handle, b in self._bodies:
                handle.position = tuple(view.body_pos[b])
                handle.wxyz = tuple(view.body_quat[b])
            if view.goal is not None:
                self._goal.position = tuple(view.goal)
                self._goal.visible = True
                self._goal_pole.points = np.array([[[view.goal[0], view.goal[1], 0.0], view.goal]])
                self._goal_pole.visible = True
            has_field = self.rt.used_field is not None
            self._arrows.points = self._arrow_points(view)
            self._arrows.visible = has_field
            if live is not None and live is not self._shown_field:
                self._shown_field = live
                self._window.points = _box_edges(np.asarray(live.grid.origin), live.grid.upper)
                self._window.visible = True
                pts = occupied_in_map(live, self.rt.perception.map.grid)
                self._occupied.points = (pts if len(pts) else np.zeros((1, 3))).astype(np.float32)
                self._occupied.colors = np.tile(np.array(MAP_RGB, dtype=np.uint8), (max(len(pts), 1), 1))
                self._occupied.visible = len(pts) > 0
        self._status.content = self._status_text(view)

    def _status_text(self, view) -> str:
        o = view.outcome
        if view.goal is None:
            return "Robot standing: no goal yet."
        state = "fallen" if o.fell else "reached" if o.reached else "walking" if view.walking else "waiting for field"
        hz = self.rt.perception.update_rate_hz()
        return (
            f"Goal ({view.goal[0]:.2f}, {view.goal[1]:.2f}) · {state} · distance {o.distance:.2f} m · "
            f"collisions {o.collisions} · field {hz:.1f} Hz"
        )

    def _render_loop(self) -> None:
        period = 1.0 / self.cfg.render_hz
        while not self._stop.is_set():
            t0 = time.monotonic()
            try:
                self.render_once()
            except Exception:  # a browser hiccup must not stop the robot
                log.exception("render failed")
            self._stop.wait(max(0.0, period - (time.monotonic() - t0)))

    def start(self) -> None:
        """Start the robot (control + perception) and the render loop in daemon threads."""
        robot = threading.Thread(target=self._run_robot, name="robot", daemon=True)
        render = threading.Thread(target=self._render_loop, name="render", daemon=True)
        self._threads = [robot, render]
        for t in self._threads:
            t.start()

    def _run_robot(self) -> None:
        try:
            self.rt.run(self._stop)
        except Exception as err:
            log.exception("robot loop stopped")
            self._show_message(f"Robot loop stopped: {err}")

    def stop(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=5.0)
        self.rt.stop()
        self.server.stop()
