"""The processes of the long evaluations (evaluation/pool.py): results in the jobs' order, a
worker's error raised in the parent, a worker's death an error rather than a hang, and a stop that
never waits on a chunk still being sent."""

import multiprocessing
import os
import signal
import threading
import time

import numpy as np
import pytest

from mbicp_viz.evaluation import pool

# A stop is seen within the pool's poll (0.1 s); ending and joining two workers takes the rest.
# A hung stop never ends (CPython issue 73945 with multiprocessing.Pool).
STOPS_WITHIN_S = 5.0
BIG = 1 << 13  # floats in a job: 64 KB, so a chunk is far more than a pipe holds (64 KB)


def _index_after_a_while(job) -> int:
    i, payload = job
    # jobs take 0-8 ms by their index: a chunk often comes back before the one sent ahead of it
    time.sleep(0.002 * ((i * 7919) % 5))
    return i + int(payload.size == 0)


def _raise_at_500(i: int) -> int:
    if i == 500:
        raise ValueError(f"job {i} is bad")
    return i


def _refuse_the_first_slowly(i: int) -> int:
    if i == 0:
        time.sleep(0.3)
    raise ValueError(f"job {i} is bad")


def _die_at_300(i: int) -> int:
    if i == 300:
        os.kill(os.getpid(), signal.SIGKILL)
    return i


def _slow(job) -> int:
    time.sleep(0.001)
    return job[0]


def test_results_come_in_the_order_of_the_jobs_however_the_workers_finish():
    jobs = ((i, np.zeros(0 if i % 3 else 100)) for i in range(600))
    got = pool.ordered_map(_index_after_a_while, jobs, workers=2, total=600)
    assert got == [i + int(i % 3 != 0) for i in range(600)]
    assert multiprocessing.active_children() == []


def test_a_workers_error_is_raised_in_the_parent_and_no_worker_is_left():
    with pytest.raises(ValueError, match="job 500 is bad"):
        pool.ordered_map(_raise_at_500, range(2000), workers=2)
    assert multiprocessing.active_children() == []


def test_the_first_error_in_the_jobs_order_is_raised_not_the_first_to_arrive():
    """As one process would meet them: job 1's error comes back first, from the other worker."""
    with pytest.raises(ValueError, match="job 0 is bad"):
        pool.ordered_map(_refuse_the_first_slowly, range(8), workers=2)
    assert multiprocessing.active_children() == []


def test_a_killed_worker_ends_the_run_with_an_error_not_a_hang():
    with pytest.raises(RuntimeError, match=r"a worker process ended in a run \(exit code -9\)"):
        pool.ordered_map(_die_at_300, range(2000), workers=2)
    assert multiprocessing.active_children() == []


@pytest.mark.parametrize("stop_after", [1, 5, 40, 64, 100, 150])
def test_a_stop_while_chunks_larger_than_a_pipe_are_sent_ends_at_once(stop_after):
    """The results so far are kept, in order, and every worker is ended, while the chunks sent
    ahead (4 MB each) are still being written to workers busy with the ones before."""
    taken: list[int] = []
    stopped_at: list[float] = []

    def take(i: int) -> None:
        taken.append(i)
        if len(taken) == stop_after:
            pool.INTERRUPTED.set()
            stopped_at.append(time.monotonic())

    jobs = ((i, np.zeros(BIG)) for i in range(10_000))
    got: list = []
    run = threading.Thread(
        target=lambda: got.extend(pool.ordered_map(_slow, jobs, 2, take, total=10_000)),
        daemon=True,
    )
    run.start()
    run.join(60.0)
    assert not run.is_alive(), "the stop hung"
    assert time.monotonic() - stopped_at[0] < STOPS_WITHIN_S
    assert stop_after <= len(taken) < 10_000 and got == taken == list(range(len(taken)))
    assert multiprocessing.active_children() == []
