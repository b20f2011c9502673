"""The debugger's controls, one per panel: each builds its panel and handles its callbacks,
driving the model (``session.state``) and asking the session to show the outcome.

Every callback runs through ``Session.guarded`` (one lock per tab; a bug is shown in the page and
the server keeps serving).
"""

from __future__ import annotations

import math
import threading

import numpy as np

from mbicp_viz.core import MATCHERS, Pose2
from mbicp_viz.errors import InputError
from mbicp_viz.readers.params_toml import presets_for

from .. import scene, viser_draw
from . import panels, report
from .camera import on_scan_plane
from .markdown import literal
from .state import DEFAULTS, TYPED, preset_name


def set_boxes(control, values: dict) -> None:
    """Put a control's checkboxes (``control.boxes``) on the model's values, with its callbacks
    quiet meanwhile (``control.showing``): viser runs a box's callback as soon as its value is
    set."""
    control.showing = True
    try:
        for key, box in control.boxes.items():
            box.value = values[key]
    finally:
        control.showing = False


class Playback:
    """The iteration slider, previous/next and the player (a thread per tab)."""

    def __init__(self, session, gui, order: float):
        self.s = session
        self.fps, self.playing = 4.0, False
        with gui.add_folder("Playback", order=order):
            self.slider = gui.add_slider(
                "iteration",
                min=0,
                max=1,
                step=1,
                initial_value=0,
                hint="0: the initial guess; the last: where the match ended",
            )
            prev_b, next_b = gui.add_button("previous"), gui.add_button("next")
            play = gui.add_checkbox("play", False)
            speed = gui.add_slider(
                "speed (iterations/s)", min=0.5, max=30.0, step=0.5, initial_value=self.fps
            )
            self.text = gui.add_markdown("")
        self.slider.on_update(lambda _: session.guarded(self._moved))
        prev_b.on_click(lambda _: session.guarded(lambda: self.step(-1)))
        next_b.on_click(lambda _: session.guarded(lambda: self.step(+1)))
        play.on_update(lambda _: setattr(self, "playing", play.value))
        speed.on_update(lambda _: setattr(self, "fps", speed.value))
        self.closed = threading.Event()
        threading.Thread(target=self._play, daemon=True).start()

    def show(self, n: int) -> None:
        """A new match of ``n`` iterations, shown where the model is (its end, or a lesson
        step's)."""
        self.slider.max = max(n, 1)
        self.slider.value = self.s.state.iteration  # the model is there already: no second redraw

    def _moved(self) -> None:
        k = int(self.slider.value)
        if k != self.s.state.iteration:
            self.s.state.iteration = k
            self.s.redraw()

    def step(self, delta: int) -> None:
        self.slider.value = int(
            np.clip(self.s.state.iteration + delta, 0, self.s.state.max_iteration())
        )

    def _play(self) -> None:
        while not self.closed.wait(1.0 / max(self.fps, 0.5)):
            if self.playing and self.s.state.runs:
                with self.s.lock:
                    if self.closed.is_set():  # closed while this frame waited for the lock
                        break
                    n = self.s.state.max_iteration()
                    self.slider.value = (
                        0 if self.s.state.iteration >= n else self.s.state.iteration + 1
                    )


class Matchers:
    """Which matchers run (one, or several compared), and the parameters of one of them."""

    def __init__(self, session, gui, order: float):
        self.s, self.gui, self.order = session, gui, order
        self.showing = False
        state = session.state
        self.edited = state.matchers[0]
        with gui.add_folder("Matchers", order=order):
            self.boxes = {
                name: gui.add_checkbox(name, name in state.matchers, hint=m.title)
                for name, m in MATCHERS.items()
            }
            self.edit = gui.add_dropdown("parameters of", list(MATCHERS), initial_value=self.edited)
            self.preset = gui.add_dropdown(
                "preset",
                self._presets(),
                initial_value=preset_name(self.edited, state.params[self.edited]),
                hint="the parameter sets shipped with the tool (--params NAME); "
                f"'{TYPED}': values typed into the boxes",
            )
        for box in self.boxes.values():
            box.on_update(lambda _: session.guarded(self._chosen))
        self.edit.on_update(lambda _: session.guarded(self._edit))
        self.preset.on_update(lambda _: session.guarded(self._preset))
        self.params: panels.ParamPanel | None = None
        self._build_params()

    def _build_params(self) -> None:
        if self.params is not None:
            self.params.folder.remove()
        self.params = panels.param_panel(
            self.gui,
            f"Parameters: {self.edited}",
            self.s.state.params[self.edited],
            self.order + 1,
            lambda name, text: self.s.guarded(lambda: self._typed(name, text)),
        )

    def _presets(self) -> list[str]:
        return [DEFAULTS, *presets_for(self.edited), TYPED]

    def _show_preset(self) -> None:
        """The picker names what the edited matcher's parameters are (its choices: that
        matcher's)."""
        self.preset.options = self._presets()
        self.preset.value = preset_name(self.edited, self.s.state.params[self.edited])

    def show(self) -> None:
        """The boxes as the model holds them (after a pair was reopened with its own matcher)."""
        set_boxes(self, {n: n in self.s.state.matchers for n in self.boxes})
        self.edited = self.edit.value = self.s.state.matchers[0]
        self._build_params()
        self._show_preset()

    def _chosen(self) -> None:
        if self.showing:  # the model sets the boxes one by one (``set_boxes``): no match in between
            return
        error = self.s.state.set_matchers([n for n, box in self.boxes.items() if box.value])
        if error:
            set_boxes(self, {n: n in self.s.state.matchers for n in self.boxes})
        self.s.clear_scene()
        self.s.after_match(error)

    def _edit(self) -> None:
        self.edited = self.edit.value
        self._build_params()
        self._show_preset()

    def _typed(self, name: str, text: str) -> None:
        """Apply one parameter as typed, or say why not; the boxes then show what the matcher
        uses."""
        self._applied(self.s.state.set_params(self.edited, {name: text}))

    def _preset(self) -> None:
        """Load the picked preset (or the defaults); picking 'as typed' or what is loaded does
        nothing."""
        state = self.s.state
        if self.preset.value in (TYPED, preset_name(self.edited, state.params[self.edited])):
            return
        self._applied(state.use_preset(self.edited, self.preset.value))

    def _applied(self, error: str | None) -> None:
        """After a change of the edited matcher's parameters: the boxes and the picker show what it
        uses, the message why a value was refused; a match that ran is shown."""
        state = self.s.state
        refused = error is not None and error != state.message  # a value, not the match, is wrong
        self.params.message.content = panels.warning(
            f"{error} — the last good value is kept" if refused else ""
        )
        self.params.show(state.params[self.edited])
        self._show_preset()
        if not refused:
            self.s.after_match(error)


class Guess:
    """The initial guess: typed, dragged in the view, or searched; and the search's parameters."""

    FIELDS = (("x", "x [m]"), ("y", "y [m]"), ("theta", "theta [deg]"))

    def __init__(self, session, gui, order: float):
        self.s = session
        self.gizmo = session.client.scene.add_transform_controls(
            "/guess",
            scale=0.8,
            disable_sliders=True,
            active_axes=(True, True, False),
            rotation_limits=((0.0, 0.0), (0.0, 0.0), (-1000.0, 1000.0)),
        )
        self.gizmo.on_update(lambda _: session.guarded(self._dragged))
        with gui.add_folder("Initial guess (object frame in the reference frame)", order=order):
            self.info = gui.add_markdown("")
            self.boxes = {
                key: panels.CommitBox(
                    gui,
                    label,
                    "",
                    "a number",
                    lambda text, key=key: session.guarded(lambda: self._typed(key, text)),
                )
                for key, label in self.FIELDS
            }
            drag = gui.add_checkbox("drag the guess in the view", True)
            drag.on_update(lambda _: setattr(self.gizmo, "visible", drag.value))
            gui.add_button(
                "search the guess",
                hint="correlative search around the current guess (search "
                "parameters below); the match restarts from its best pose",
            ).on_click(
                lambda _: session.guarded(lambda: session.after_match(session.state.search_guess()))
            )
        self.search = panels.param_panel(
            gui,
            "Search parameters",
            session.state.search,
            order + 1,
            lambda name, text: session.guarded(lambda: self._search_typed(name, text)),
        )

    def show(self) -> None:
        g, state = self.s.state.guess, self.s.state
        for key, value in (("x", g.x), ("y", g.y), ("theta", math.degrees(g.theta))):
            self.boxes[key].show(repr(round(value, 9)))
        self.info.content = f"from: {state.guess_source}"
        self.gizmo.position, self.gizmo.wxyz = (g.x, g.y, 0.0), viser_draw.yaw_to_wxyz(g.theta)

    def _typed(self, key: str, text: str) -> None:
        try:
            value = float(text)
        except ValueError:
            self.s.say(f"initial guess {key}: not a number: {text!r}")
            self.show()
            return
        g = self.s.state.guess
        x, y, theta = (
            value if key == k else v
            for k, v in (("x", g.x), ("y", g.y), ("theta", math.degrees(g.theta)))
        )
        self.s.after_match(self.s.state.set_guess(Pose2(x, y, math.radians(theta))))

    def _dragged(self) -> None:
        x, y, _ = (float(v) for v in self.gizmo.position)
        self.s.after_match(
            self.s.state.set_guess(Pose2(x, y, viser_draw.wxyz_to_yaw(self.gizmo.wxyz)), "dragged")
        )

    def _search_typed(self, name: str, text: str) -> None:
        error = self.s.state.set_search({name: text})
        self.search.message.content = panels.warning(
            f"{error} — the last good value is kept" if error else ""
        )
        self.search.show(self.s.state.search)


class Scans:
    """Which two scans of a log are matched, and which of its scan streams (a bag's topics, a CARMEN
    log's laser message types)."""

    def __init__(self, session, gui, order: float):
        self.s = session
        state = session.state
        log = state.source.log
        with gui.add_folder("Scans", order=order):
            self.info = gui.add_markdown("")
            # an evaluation's rows hold to one topic
            if len(log.scan_topics) > 1 and not state.source.rows_label:
                self.topic = gui.add_dropdown(
                    "scan stream",
                    list(log.scan_topics),
                    initial_value=log.topic,
                    hint="; ".join(f"{t}: {d}" for t, d in log.scan_topics.items()),
                )
                self.topic.on_update(lambda _: session.guarded(self._topic))
            self.consecutive = gui.add_checkbox("consecutive (object = reference + 1)", True)
            self.ref = panels.CommitBox(
                gui,
                "reference scan",
                str(state.pair[0]),
                "a scan number",
                lambda text: session.guarded(lambda: self._typed(ref=text)),
            )
            self.obj = panels.CommitBox(
                gui,
                "object scan",
                str(state.pair[1]),
                "a scan number",
                lambda text: session.guarded(lambda: self._typed(obj=text)),
            )
        self._show_records()

    def _typed(self, ref: str | None = None, obj: str | None = None) -> None:
        pair = self.s.state.pair
        try:
            i = int(ref) if ref is not None else pair[0]
            j = i + 1 if self.consecutive.value else (int(obj) if obj is not None else pair[1])
        except ValueError:
            error = "scan numbers must be whole numbers"
        else:
            error = self.s.state.set_pair(i, j)
        self.open(error)

    def _show_records(self) -> None:
        log = self.s.state.source.log
        self.info.content = (
            f"records 0 .. {log.records - 1}"
            + (f" of {literal(log.topic)}" if log.topic else "")
            + (f" ({len(log.known_unusable)} unusable)" if log.known_unusable else "")
        )

    def _topic(self) -> None:
        error = self.s.state.set_topic(self.topic.value)
        if error:
            self.topic.value = self.s.state.source.log.topic
        self.s.show_notes()
        self.open(error)

    def open(self, error: str | None) -> None:
        """Show the pair the model holds (a new one, or the last good one with why not)."""
        if not error:
            self.s.clear_scene()
        self._show_records()
        self.ref.show(str(self.s.state.pair[0]))
        self.obj.show(str(self.s.state.pair[1]))
        self.s.after_match(error)
        self.s.fit_view()


class Layers:
    """A checkbox per kind of layer, and the iso-distance curves of a chosen object point."""

    def __init__(self, session, gui, order: float):
        self.s, self.showing = session, False
        with gui.add_folder("Layers", order=order):
            self.boxes = {}
            for style in scene.STYLES:
                box = gui.add_checkbox(style.label, session.state.visible[style.label])
                box.on_update(
                    lambda ev, label=style.label: session.guarded(
                        lambda: self._toggled(label, ev.target.value)
                    )
                )
                self.boxes[style.label] = box
            self.iso = panels.CommitBox(
                gui,
                "iso-curves of object point",
                "",
                "click a blue point in the view, or type its index (empty: a few spread)",
                lambda text: session.guarded(lambda: self._iso_typed(text)),
            )
        session.client.scene.on_click()(
            lambda ev: session.guarded(lambda: self.click(ev.ray_origin, ev.ray_direction))
        )

    def show(self) -> None:
        """The boxes as the model holds them (a lesson step opens with its own layers)."""
        set_boxes(self, self.s.state.visible)

    def offered(self, state) -> None:
        """Only the boxes of layers this pair can have: the scans as measured where one is
        corrected for motion, the 360-degree seam where the reference closes the circle."""
        try:
            ref, obj = state.ref, state.obj
        except InputError:  # an unusable scan: the page says so, the boxes stay
            return
        has = {
            scene.RAW.label: ref.raw is not None or obj.raw is not None,
            scene.SEAM.label: ref.is_full_circle(),
        }
        for label, box in self.boxes.items():
            box.visible = has.get(label, True)

    def _toggled(self, label: str, value: bool) -> None:
        # the model sets the boxes (``set_boxes``): one redraw after, not one per box
        if self.showing:
            return
        self.s.state.visible[label] = bool(value)
        self.s.redraw()

    def _iso_typed(self, text: str) -> None:
        if text and not text.isdigit():
            self.s.say(f"iso-curves: an object point index, got {text!r}")
            return
        self.s.state.iso_point = int(text) if text else None
        self._show_teaching()

    def click(self, origin, direction) -> int | None:
        """Choose the object point nearest to where a view ray meets the scan plane (z = 0); in
        the run view the run's click is the one that counts."""
        at = on_scan_plane(origin, direction)
        if at is None or not self.s.state.runs or (self.s.run is not None and self.s.run.active):
            return None
        self.s.state.iso_point = report.nearest_object_point(self.s.state, at)
        self.iso.show(str(self.s.state.iso_point))
        self._show_teaching()
        return self.s.state.iso_point

    def _show_teaching(self) -> None:
        if self.s.state.iso_point is not None:
            for style in (scene.ISO_METRIC, scene.ISO_EUCLID):
                self.s.state.visible[style.label] = True
            self.show()
        self.s.redraw()


class PairList:
    """Pairs of an evaluation to open (``serve LOG --rows FILE``): its failures, worst first, or
    its suspicious pairs found without truth, the most suspicious first; each with its reason.
    Choosing one reopens it exactly as the evaluation ran it."""

    MAX_LISTED = 500  # a dropdown longer than this is no longer read; the file keeps them all

    def __init__(
        self, session, gui, order: float, title: str, rows, label, order_text: str, pick: str
    ):
        self.s = session
        shown = rows[: self.MAX_LISTED]
        self.rows = {label(k + 1, r): r for k, r in enumerate(shown)}
        # the file's name inside: a long folder title wraps over the controls above it
        with gui.add_folder(title, order=order):
            rows_label = literal(session.state.source.rows_label)
            if not shown:
                gui.add_markdown(f"no {title.lower()} among {rows_label}")
                return
            gui.add_markdown(
                f"{len(rows)} {order_text}"
                + (f"; the first {len(shown)} are listed" if len(rows) > len(shown) else "")
                + f" ({rows_label})"
            )
            self.pick = gui.add_dropdown(pick, list(self.rows), initial_value=next(iter(self.rows)))
        self.picked = self.pick.value
        self.pick.on_update(lambda _: session.guarded(self._picked))

    def _picked(self) -> None:
        # a list opened and closed again sends its value unchanged: that opens nothing
        if self.pick.value == self.picked:
            return
        self.picked = self.pick.value
        self.s.open_row(self.rows[self.pick.value])
