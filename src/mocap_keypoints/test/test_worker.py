import threading
import time

import pytest

from mocap_keypoints.sources import Frame, SourceError
from mocap_keypoints.worker import LatestWorker, SourceFeeder


class Collector:
    def __init__(self):
        self.items, self.errors = [], []
        self.lock = threading.Lock()

    def __call__(self, item, result, error, seconds):
        with self.lock:
            (self.errors if error else self.items).append((item, result, error, seconds))


def _slow(seconds):
    def process(item):
        time.sleep(seconds)
        return item * 10
    return process


def test_latest_worker_processes_the_newest_and_counts_drops():
    out = Collector()
    w = LatestWorker(_slow(0.05), out).start()
    for i in range(10):
        w.submit(i)
        time.sleep(0.005)
    assert w.wait_idle(5.0)
    w.stop()
    got = [item for item, *_ in out.items]
    assert got[0] == 0 and got[-1] == 9          # the first, then always the newest
    assert len(got) <= 5 and w.dropped == 10 - len(got)
    assert w.processed == len(got) and w.submitted == 10
    assert all(r == i * 10 for i, r, _, _ in out.items)
    assert all(s >= 0.045 for *_, s in out.items)


def test_blocking_submit_drops_nothing_and_keeps_order():
    out = Collector()
    w = LatestWorker(_slow(0.01), out).start()
    for i in range(15):
        assert w.submit(i, block=True) == 0
    assert w.wait_idle(5.0)
    w.stop()
    assert [item for item, *_ in out.items] == list(range(15)) and w.dropped == 0


def test_exceptions_are_reported_and_the_worker_goes_on():
    out = Collector()

    def process(item):
        if item == 1:
            raise RuntimeError('model exploded')
        return item

    w = LatestWorker(process, out).start()
    for i in range(3):
        w.submit(i, block=True)
    assert w.wait_idle(5.0)
    w.stop()
    assert [i for i, *_ in out.items] == [0, 2] and w.failed == 1
    assert isinstance(out.errors[0][2], RuntimeError)


# --- two threads: process, then finish ------------------------------------------------------
def test_finish_runs_beside_the_next_items_processing_and_keeps_the_order():
    """finish(k) runs while item k + 1 is processed (it waits for that to start: without the
    second thread it would wait in vain), the results come out in order, finished, and the
    seconds count both calls."""
    out = Collector()
    started = {i: threading.Event() for i in range(6)}
    overlapped = []

    def process(item):
        started[item].set()
        return item * 10

    def finish(result):
        item = result // 10
        if item + 1 in started:
            overlapped.append(started[item + 1].wait(10.0))
        time.sleep(0.002)
        return result + 1

    w = LatestWorker(process, out, finish=finish).start()
    for i in range(6):
        assert w.submit(i, block=True) == 0
    assert w.wait_idle(10.0)
    w.stop()
    assert overlapped == [True] * 5
    assert [(i, r) for i, r, *_ in out.items] == [(i, i * 10 + 1) for i in range(6)]
    assert w.processed == 6 and w.dropped == 0 and not w.running
    assert all(s >= 0.0015 for *_, s in out.items)


class HeldFinish:
    """``process`` records the items it starts; ``finish`` holds item 0 until ``release``
    (``finishing`` is set meanwhile)."""

    def __init__(self):
        self.release, self.finishing = threading.Event(), threading.Event()
        self.done = []
        self.cond = threading.Condition()

    def process(self, item):
        with self.cond:
            self.done.append(item)
            self.cond.notify_all()
        return item

    def finish(self, result):
        if result == 0:
            self.finishing.set()
            assert self.release.wait(10.0)
        return result

    def wait_done(self, n):
        with self.cond:
            assert self.cond.wait_for(lambda: len(self.done) >= n, 10.0)

    def worker_holding(self, out) -> LatestWorker:
        """A two-thread worker with item 0 held in finish and item 1 processed."""
        w = LatestWorker(self.process, out, finish=self.finish).start()
        w.submit(0)
        assert self.finishing.wait(10.0)
        w.submit(1)
        self.wait_done(2)
        return w


def test_at_most_one_result_waits_between_the_two_threads():
    """While finish is held, the first thread hands over one result, processes one more and
    waits; newer items replace each other in the input slot (counted), as with one thread."""
    out = Collector()
    h = HeldFinish()
    w = h.worker_holding(out)    # 1 handed over, waiting for finish
    assert not w.wait_idle(0.0) and not w.idle
    w.submit(2)
    h.wait_done(3)               # processed; the thread waits for the hand-off
    for i in range(3, 10):
        w.submit(i)
    h.release.set()
    assert w.wait_idle(10.0)
    w.stop()
    assert [i for i, *_ in out.items] == [0, 1, 2, 9]
    assert w.dropped == 6 and w.processed == 4 and h.done == [0, 1, 2, 9]


def test_errors_of_either_thread_are_reported_in_order():
    got = []

    def on_result(item, result, error, seconds):
        got.append((item, result, type(error).__name__ if error else None))

    def process(item):
        if item == 1:
            raise RuntimeError('detector')
        return item

    def finish(result):
        if result == 2:
            raise ValueError('estimate')
        return -result

    w = LatestWorker(process, on_result, finish=finish).start()
    for i in range(4):
        w.submit(i, block=True)
    assert w.wait_idle(10.0)
    w.stop()
    assert got == [(0, 0, None), (1, None, 'RuntimeError'), (2, None, 'ValueError'),
                   (3, -3, None)]
    assert w.processed == 2 and w.failed == 2


def test_stop_discards_what_waits_and_ends_both_threads():
    """Stopped while finish is held, the first thread waiting on the hand-off and a third item
    in the input slot: stop returns once the held item is through, the waiting items are
    discarded, and waiting for idle does not hang."""
    out = Collector()
    h = HeldFinish()
    w = h.worker_holding(out)
    w.submit(2)                 # 1 is handed over or about to be; 2 waits
    stopper = threading.Thread(target=w.stop, kwargs={'timeout': 10.0})
    stopper.start()
    with w._cond:
        assert w._cond.wait_for(lambda: w._stop, 10.0)
    h.release.set()
    stopper.join(10.0)
    assert not stopper.is_alive() and not w.running
    assert [i for i, *_ in out.items] == [0]
    assert not w.wait_idle(None) or w.idle       # returns at once after stop


def test_a_failing_consumer_is_counted_and_the_worker_goes_on():
    got = []

    def on_result(item, result, error, seconds):
        if item == 1:
            raise RuntimeError('consumer')
        got.append(item)

    w = LatestWorker(lambda x: x, on_result, finish=lambda r: r).start()
    for i in range(3):
        w.submit(i, block=True)
    assert w.wait_idle(10.0)
    w.stop()
    assert got == [0, 2] and w.callback_errors == 1
    assert str(w.callback_error) == 'consumer'


class FakeSource:
    def __init__(self, n, fps, live=False, fail_at=None):
        self.n, self.fps, self.live, self.fail_at = n, fps, live, fail_at
        self.ended_reason = ''

    def __iter__(self):
        for i in range(self.n):
            if i == self.fail_at:
                raise SourceError('camera unplugged')
            if self.live:
                time.sleep(1.0 / self.fps)
            yield Frame(int(i * 1e9 / self.fps), None, i)
        self.ended_reason = f'all {self.n} read'


def _feed(source, process_s, realtime):
    out = Collector()
    ended = []
    w = LatestWorker(lambda f: f.index, out) if process_s == 0 else \
        LatestWorker(lambda f: time.sleep(process_s) or f.index, out)
    w.start()
    feeder = SourceFeeder(source, w, realtime=realtime,
                          on_end=lambda reason, err: ended.append((reason, err))).start()
    assert feeder.finished.wait(10.0)
    assert w.wait_idle(5.0)
    w.stop()
    return out, w, feeder, ended


def test_realtime_feeding_is_paced_and_drops_what_the_worker_cannot_take():
    t0 = time.monotonic()
    out, w, feeder, ended = _feed(FakeSource(30, fps=100.0), process_s=0.03, realtime=True)
    elapsed = time.monotonic() - t0
    assert elapsed >= 0.28                         # 30 frames at 100 fps: paced
    assert 5 <= len(out.items) <= 16 and w.dropped == 30 - len(out.items)
    assert out.items[-1][0].index == 29            # the newest frame is never lost
    assert ended == [('all 30 read', None)]


def test_as_fast_as_possible_feeding_drops_nothing():
    t0 = time.monotonic()
    out, w, feeder, ended = _feed(FakeSource(20, fps=10.0), process_s=0.005, realtime=False)
    assert time.monotonic() - t0 < 1.5             # not paced at 10 fps (would take 2 s)
    assert [f.index for f, *_ in out.items] == list(range(20)) and w.dropped == 0


def test_live_sources_always_drop_and_failures_are_reported():
    out, w, feeder, ended = _feed(FakeSource(40, fps=200.0, live=True), process_s=0.02,
                                  realtime=False)
    assert w.dropped > 0 and feeder.drop
    out, w, feeder, ended = _feed(FakeSource(10, fps=100.0, fail_at=4), 0, realtime=False)
    assert len(out.items) == 4
    reason, err = ended[0]
    assert isinstance(err, SourceError) and 'unplugged' in reason


def test_stopping_a_feeder_mid_stream():
    w = LatestWorker(lambda f: f.index, Collector()).start()
    ended = []
    feeder = SourceFeeder(FakeSource(1000, fps=50.0), w, realtime=True,
                          on_end=lambda r, e: ended.append(r)).start()
    time.sleep(0.1)
    feeder.stop()
    w.stop()
    assert feeder.finished.is_set() and ended == ['stopped']
    assert w.submit(1) == 0  # a stopped worker ignores new items


@pytest.mark.parametrize('block', [False, True])
def test_stop_wakes_a_waiting_producer(block):
    started = threading.Event()

    def process(item):
        started.set()
        time.sleep(0.2)

    w = LatestWorker(process, Collector()).start()
    w.submit(0)
    started.wait(2.0)
    w.submit(1)
    threading.Timer(0.05, w.stop).start()
    t0 = time.monotonic()
    w.submit(2, block=block, timeout=2.0)
    assert time.monotonic() - t0 < 1.0
