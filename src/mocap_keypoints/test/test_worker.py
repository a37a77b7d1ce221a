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
