"""Inline in Jupyter: a match or a run in rerun's notebook viewer (the ``rerun-notebook`` widget,
``pip install "mbicp-viz[notebook]"``), with the same blueprint and the same data as its ``.rrd``
(``views/rrd.py`` logs both)."""

from __future__ import annotations

from mbicp_viz.errors import InputError
from mbicp_viz.readers.pair_match import PairMatch

from . import rrd

WIDTH, HEIGHT = 960, 640  # [px] room for the scans beside the plots


def _viewer(stream, blueprint, width: int, height: int):
    """rerun's notebook widget fed by ``stream`` (everything logged to it goes to the widget)."""
    from rerun.notebook import HAS_NOTEBOOK, Viewer

    if not HAS_NOTEBOOK:
        raise InputError(
            'showing inline needs rerun\'s notebook widget: pip install "mbicp-viz[notebook]"'
        )
    return Viewer(width=width, height=height, recording=stream, blueprint=blueprint)


def match_viewer(
    matches: list[PairMatch],
    teaching: bool = False,
    width: int = WIDTH,
    height: int = HEIGHT,
    recording_id: str = "mbicp-viz",
):
    """A widget showing ``matches`` (each with its events) as ``rrd.record`` writes them."""
    stream = rrd.new_stream(recording_id)
    viewer = _viewer(stream, rrd.pair_blueprint(matches, teaching), width, height)
    rrd.log_matches(stream, matches, teaching)
    return viewer


def run_viewer(
    log,
    rows: list[PairMatch],
    width: int = WIDTH,
    height: int = HEIGHT,
    recording_id: str = "mbicp-viz/sequence",
):
    """A widget showing a run (``eval sequence``'s rows) as ``rrd.record_sequence`` writes it."""
    stream = rrd.new_stream(recording_id)
    viewer = _viewer(stream, rrd.sequence_blueprint(rows), width, height)
    rrd.log_sequence(stream, log, rows)
    return viewer
