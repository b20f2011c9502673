"""What a front end costs: each consecutive pair matched and recorded to an .rrd (``bench
matches --rrd``)."""

from __future__ import annotations

import os
import tempfile
import time

import numpy as np

from mbicp_viz.core import Params
from mbicp_viz.evaluation.bench import Timing
from mbicp_viz.evaluation.pairs import stored_guess
from mbicp_viz.evaluation.single import Setup, match_pair

from .rrd import record


def time_recordings(log, params: Params, limit: int | None, repeat: int, teaching: bool):
    """Time for matching and writing each consecutive pair to an .rrd, and the file sizes
    [bytes]."""
    times, sizes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "bench.rrd")
        for i, j in log.consecutive_pairs(limit):
            ref, obj = log.scan(i), log.scan(j)
            s = Setup(*stored_guess(ref, obj), None, None)
            for _ in range(repeat):
                t0 = time.perf_counter()
                m = match_pair(ref, obj, params, s, log.frames, record=True)
                record([m], path, teaching=teaching)
                times.append(1000.0 * (time.perf_counter() - t0))
                sizes.append(os.path.getsize(path))
    return Timing("recording to .rrd", np.array(times)), np.array(sizes)
