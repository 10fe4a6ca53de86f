"""A Ctrl-C during a campaign prints one line, not Dask's traceback of a known bug.

``distributed.utils.sync`` (how the client waits) schedules a ``cancel`` callback when a
KeyboardInterrupt lands in its wait; if its coroutine has not assigned ``future`` yet, that
callback raises NameError and tornado logs the traceback at ERROR (seen on a loaded machine,
where it broke the interrupt tests' one-line check). The campaign drops exactly that record
(:class:`scenarios.campaign.execute.SyncCancelBugFilter`). Here the bug is made to happen on a
real Dask loop thread: sync's first wait is interrupted at once, before its coroutine runs.
"""
from __future__ import annotations

import logging
import threading

import pytest
from distributed import utils as dask_utils

from scenarios.campaign.execute import SyncCancelBugFilter, _filter_sync_cancel_bug


class _Threading:
    """``threading`` for ``distributed.utils``, with an Event whose first wait is interrupted."""

    class Event(threading.Event):
        def wait(self, timeout=None):
            if not getattr(self, "interrupted", False):
                self.interrupted = True
                raise KeyboardInterrupt
            return super().wait(timeout)

    def __getattr__(self, name):
        return getattr(threading, name)


class _Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records = []

    def emit(self, record):
        self.records.append(record)


@pytest.fixture
def tornado_log(monkeypatch):
    """tornado's callback logger without filters, and the records that pass it."""
    logger = logging.getLogger("tornado.application")
    monkeypatch.setattr(logger, "filters", [])
    handler = _Records()
    logger.addHandler(handler)
    yield logger, handler.records
    logger.removeHandler(handler)


def _interrupted_sync(monkeypatch, then=None) -> None:
    """Run ``sync`` on a real Dask loop thread, interrupted before its coroutine starts; return
    once the loop has run sync's callbacks (and ``then``, scheduled after them)."""
    async def work():
        return 1

    runner = dask_utils.LoopRunner(asynchronous=False)
    runner.start()
    # the loop thread waits at this gate until sync has been interrupted: sync's coroutine cannot
    # finish first (then sync would never wait, and nothing would interrupt it)
    gate = threading.Event()
    runner.loop.add_callback(gate.wait, 30)
    try:
        try:
            with monkeypatch.context() as m:
                m.setattr(dask_utils, "threading", _Threading())
                with pytest.raises(KeyboardInterrupt):
                    dask_utils.sync(runner.loop, work)
        finally:
            gate.set()
        if then is not None:
            runner.loop.add_callback(then)
        done = threading.Event()
        runner.loop.add_callback(done.set)
        assert done.wait(10)
    finally:
        runner.stop()


def _name_errors(records):
    return [r for r in records if r.exc_info and isinstance(r.exc_info[1], NameError)]


def test_the_dask_bug_happens_here_without_the_filter(monkeypatch, tornado_log):
    """If this fails, Dask has fixed the bug: the filter can go."""
    _, records = tornado_log
    _interrupted_sync(monkeypatch)
    assert len(_name_errors(records)) == 1 and "future" in str(records[0].exc_info[1])


def test_the_campaign_drops_that_record_and_no_other(monkeypatch, tornado_log):
    logger, records = tornado_log
    _filter_sync_cancel_bug()
    _filter_sync_cancel_bug()  # once per process
    assert sum(isinstance(f, SyncCancelBugFilter) for f in logger.filters) == 1

    def another_error():
        raise NameError("an error of ours")

    _interrupted_sync(monkeypatch, then=another_error)
    assert [str(r.exc_info[1]) for r in _name_errors(records)] == ["an error of ours"]
