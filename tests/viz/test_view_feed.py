"""The view's thread at close: a slow view is waited for, a stuck one is given up on, both bounded."""

from __future__ import annotations

import threading
import time

import pytest

from tankdaq.viz.view_feed import ViewFeed


def _raise(exc: BaseException) -> None:
    raise AssertionError(f"a job raised: {exc!r}")


def _slow_jobs(feed: ViewFeed, count: int, each_s: float) -> None:
    for _ in range(count):
        feed.put(lambda: time.sleep(each_s), droppable=False)


@pytest.mark.slow
def test_a_slow_view_is_waited_for_past_the_stall_bound_and_finishes() -> None:
    """80 updates of at least 50 ms take 4 s or more, twice the 2 s no-progress bound: all are done."""
    feed = ViewFeed(on_error=_raise)
    _slow_jobs(feed, 80, 0.05)
    start = time.monotonic()
    assert feed.stop(stall_s=2.0)
    assert time.monotonic() - start >= 2.0  # longer than the stall bound: a fixed bound would cut it
    assert feed.done == 80


def test_a_stuck_view_is_given_up_on_after_the_stall_bound() -> None:
    feed = ViewFeed(on_error=_raise)
    release = threading.Event()
    feed.put(release.wait, droppable=False)  # a flush to a viewer that never answers
    feed.put(lambda: None, droppable=False)
    try:
        assert not feed.stop(stall_s=0.3)
        assert feed.done == 0
    finally:
        release.set()


def test_a_view_that_gets_on_is_still_given_up_on_at_the_overall_limit() -> None:
    feed = ViewFeed(on_error=_raise)
    _slow_jobs(feed, 80, 0.05)
    assert not feed.stop(stall_s=60.0, limit_s=0.5)
    assert feed.done < 80
