"""A log's own no-return code: the value a laser writes where it saw nothing, found in its readings.

Logs that state no maximum range still write one value (or a band of a few centimetres) for every
beam without a return: aces writes 50.00 m, others 51.0-51.3 m or 32.76 m. Kept, those become a
wall of false points at the end of every empty beam. Such a code is a spike at the top of the
stream's readings — thousands of one value with nearly nothing above it and far fewer readings
just below it — which real surfaces do not make: a fixed mask of 50.00 m would instead drop real
readings in the logs of longer-range lasers.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from mbicp_viz.core import UnusableScan

from .log import ScanLog

BIN_M = 0.01  # readings are binned to the centimetre, the step of CARMEN's logs
MIN_SHARE = 0.001  # a code is at least this share of the readings ...
MIN_COUNT = 20  # ... and this many
BAND_M = 1.0  # a code spreads over at most this much
BELOW_M = 5.0  # the readings of real surfaces are compared over this much below the band
SPIKE = 10.0  # a code's bins hold this many times the density below them
ABOVE_SHARE = 0.01  # readings above a code: at most this share of the code's count
REAL_SHARE = 0.25  # readings below a code: at least this share of its count (a log whose
# readings are nearly all one value is not read as all no return)
MAX_CODES = 3  # codes searched one below the other


def find_ceiling(ranges: np.ndarray) -> tuple[float, float, int] | None:
    """(lowest code value, highest, count) of the spike at the top of ``ranges`` [m], or None.

    The readings are grouped, from the top down, into bands of centimetre bins with gaps of at most
    two empty bins; the first band that holds enough readings, with almost none above it, many
    times the density of the readings below it and real readings below it, is the code. The search
    stops at a band wider than ``BAND_M`` (the dense readings of real surfaces)."""
    if len(ranges) == 0:
        return None
    bins = np.rint(ranges / BIN_M).astype(np.int64)
    first = int(bins.min())
    counts = np.bincount(bins - first)
    filled = np.flatnonzero(counts)[::-1]
    need = max(MIN_COUNT, MIN_SHARE * len(ranges))
    above, k = 0, 0
    while k < len(filled) and above <= ABOVE_SHARE * len(ranges):
        hi = lo = int(filled[k])
        while k + 1 < len(filled) and lo - filled[k + 1] <= 3:
            k += 1
            lo = int(filled[k])
        k += 1
        if (hi - lo) * BIN_M > BAND_M:
            return None
        code = int(counts[lo : hi + 1].sum())
        below = counts[max(0, lo - int(BELOW_M / BIN_M)) : lo]
        spiky = code / (hi - lo + 1) >= SPIKE * float(below.mean() if len(below) else 0.0)
        real = counts[:lo].sum() >= REAL_SHARE * code
        if code >= need and above <= ABOVE_SHARE * code and spiky and real:
            return (first + lo) * BIN_M, (first + hi) * BIN_M, code
        above += code
    return None


def mask_ceiling(log: ScanLog) -> list[str]:
    """Masks the log's no-return codes (``find_ceiling``, one below the other) as invalid readings,
    in place; a scan left with none becomes unusable. Returns a note for each code masked."""
    notes = []
    for _ in range(MAX_CODES):
        readings = np.concatenate([s.ranges[s.valid] for s in log.scans]) if log.scans else []
        found = find_ceiling(np.asarray(readings, dtype=float))
        if found is None:
            break
        lo, hi, count = found
        cut = lo - BIN_M / 2
        records = log.record_numbers()
        kept = []
        for record, s in zip(records, log.scans):
            valid = s.valid & (s.ranges < cut)
            if valid.any():
                kept.append(replace(s, valid=valid))
            else:
                log.unusable[record] = UnusableScan(
                    s.source, "no valid reading: all are the log's no-return code"
                )
        log.scans = kept
        span = f"{lo:.2f} m" if hi - lo < BIN_M / 2 else f"{lo:.2f}-{hi:.2f} m"
        notes.append(
            f"{log.path}: {count} readings of {span} ({100 * count / len(readings):.1f} % of the "
            "readings, nearly none beyond) read as the laser's no-return code, not points"
        )
    return notes
