"""The interactive debugger in the browser (viser): one server, one ``Session`` per tab.

Safe by default: the server binds 127.0.0.1, and a websocket whose ``Origin`` is not the
debugger's own page is closed before anything is sent to it or read from it, from the first
connection the port accepts (viser itself accepts any origin, so a page open in the same browser
could otherwise drive the debugger and read the scans). The matchers' kernels compile (or load
from numba's cache) while the server starts; a tab that connects meanwhile says so. After an
install they compile in a background process and the tabs match at once, interpreted, saying so
until the compiled code is ready.
"""

from __future__ import annotations

import functools
import sys
import tempfile
import threading
import traceback
from collections.abc import Iterator
from contextlib import contextmanager, redirect_stdout
from pathlib import Path

import viser

from mbicp_viz.core import MATCHERS, match, tiers
from mbicp_viz.core.budget import Halt, limited

from .camera import TopDownCamera
from .session import Session
from .state import Source


def local_origins(host: str, port: int) -> set[str]:
    """The origins of the debugger's own page, as browsers send them."""
    names = {"127.0.0.1", "localhost"} if host in ("127.0.0.1", "0.0.0.0", "localhost") else {host}
    return {f"http://{n}:{port}" for n in names}


_START = threading.Lock()  # one server starting at a time: the guard below is put in place for it


@contextmanager
def checked_from_the_start(check) -> Iterator[None]:
    """Every viser server started within the block runs ``check(websocket_server, connection)``
    first of all its connect callbacks. viser (1.1) starts listening inside ``ViserServer()`` and
    has no origin hook: a check added after the constructor leaves the port open without it (for
    the whole kernel compile, once). Its websocket layer runs the connect callbacks, in the event
    loop, before any message of the connection is sent or handled."""
    start = viser.infra.WebsockServer.start

    def guarded(ws) -> None:
        ws._client_connect_cb.insert(0, functools.partial(check, ws))
        start(ws)

    with _START:
        viser.infra.WebsockServer.start = guarded
        try:
            yield
        finally:
            viser.infra.WebsockServer.start = start


def viser_server(host: str, port: int) -> viser.ViserServer:
    """A viser server whose banner goes to stderr (stdout is a command's data: ``live``'s
    pairs), lit for a top-down view of dots and lines: no shadows and no environment map, which
    such a view never shows and a browser drawing WebGL in software pays for at every frame (the
    Intel run view's slider step in headless Chromium: 0.68 s with them, 0.48 s without)."""
    with redirect_stdout(sys.stderr):
        server = viser.ViserServer(host=host, port=port, verbose=False)
    server.scene.configure_default_lights(True, cast_shadow=False)
    server.scene.configure_environment_map(hdri=None)
    return server


def stop_server(server: viser.ViserServer) -> None:
    """Stop a viser server; its farewell goes to stderr, as its banner (``viser_server``)."""
    with redirect_stdout(sys.stderr):
        server.stop()


class App:
    """A viser server with one Session per connected browser tab, or on a live run
    (``live.run.LiveRun``, ``source`` None) one ``live.LiveTab`` per tab."""

    def __init__(
        self,
        source: Source | None,
        host: str = "127.0.0.1",
        port: int = 8080,
        allow_origins: tuple[str, ...] = (),
        live=None,
    ):
        # a person waits on this page: never a compile stall (before any kernel runs)
        tiers.quick_start()
        self.source, self.host, self.allow_origins = source, host, set(allow_origins)
        self.live = live
        # a live tab's frozen buffers, removed with the server
        self.folder = tempfile.TemporaryDirectory(prefix="mbicp-viz-live-") if live else None
        self.sessions: dict[int, Session] = {}
        self.refused: dict[int, str] = {}  # client id -> the origin whose websocket was closed
        self._lock = threading.Lock()
        self.ready = threading.Event()
        with checked_from_the_start(self._check_origin):
            self.server = viser_server(host, port)
        if live is not None:  # its matcher's kernels are loaded: it is matching
            self.ready.set()
        else:  # where every tab starts
            TopDownCamera(self.server).fit(source.log.scan(source.pair[0]).points())
            threading.Thread(target=self._warm_up, daemon=True).start()
            if source.run is not None:  # the run view's model, ready before the first tab asks
                threading.Thread(target=self._warm_run, daemon=True).start()
        self.server.on_client_connect(self._connect)
        self.server.on_client_disconnect(self._disconnect)

    @property
    def port(self) -> int:
        return self.server.get_port()

    def _warm_up(self) -> None:
        """Make every kernel the tabs will run ready, and in lesson mode every step's (a later step
        then opens without a compile stall): compiled here, or loaded from numba's cache. After an
        install (core/tiers.py's quick start) a background process compiles them while the tabs
        match at once, interpreted; then they are loaded from the cache it wrote."""
        try:
            from .state import MATCH_ERRORS, DebugState

            state = DebugState(self.source)
            # every step's
            lesson = [name for step in self.source.lesson for name in step.scenario.params]
            names = list(dict.fromkeys([*state.matchers, *lesson]))
            for name in names:
                MATCHERS[name].load()
            if tiers.compile_in_background():
                self.ready.set()
                tiers.wait_compiled()
            # a match of each, so that its kernels are loaded now: one iteration is enough
            done = Halt()
            done.stop("warmed up")
            with limited(None, done):
                for name in names:
                    match(state.ref, state.obj, state.guess, state.params[name])
        except MATCH_ERRORS:  # the session's own match says what is wrong with the input
            pass
        except Exception:  # a bug: the session shows its own, the server keeps serving
            traceback.print_exc()
        finally:
            self.ready.set()
            with self._lock:
                sessions = list(self.sessions.values())
            for s in sessions:
                s.compiled()

    def _warm_run(self) -> None:
        from .run_model import tab_model

        try:
            tab_model(self.source)
        except Exception:  # the first tab computes it again and shows what is wrong
            traceback.print_exc()

    async def _check_origin(self, ws, conn) -> None:
        connection = ws._live_connections.get(conn.client_id)
        if connection is None:
            return
        origin = connection.request.headers.get("Origin")
        # the port the connection came in on: the server's own, known here before get_port()
        if origin not in local_origins(self.host, connection.local_address[1]) | self.allow_origins:
            self.refused[conn.client_id] = str(origin)
            await connection.close(1008, "origin not allowed")

    def _connect(self, client: viser.ClientHandle) -> None:
        if client.client_id in self.refused:  # a message that arrived before the close
            return
        if self.live is not None:
            from .live import LiveTab

            tab = LiveTab(client, self.live, Path(self.folder.name), self.live.budget_s)
            with self._lock:
                self.sessions[client.client_id] = tab
            return
        session = Session(client, self.source, self.ready)
        with self._lock:
            self.sessions[client.client_id] = session
        session.first_match(self.ready)

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            s = self.sessions.pop(client.client_id, None)
        if s is not None:
            s.close()

    def stop(self) -> None:
        for s in list(self.sessions.values()):
            s.close()
        stop_server(self.server)
        # a recorder runs only once a session was exported; importing rerun to find none would
        # make a stop 0.3 s slower
        if (rrd := sys.modules.get("mbicp_viz.views.rrd")) is not None:
            rrd.stop_recorder()
        if self.folder is not None:
            self.folder.cleanup()
