"""Running the detector beside the ROS executor without queueing stale frames (no ROS imports).

:class:`LatestWorker` owns one thread that processes items one at a time. Between the
producer and that thread sits a single slot: a new item replaces an item still waiting there
(counted in ``dropped``), so at most one frame waits while one is processed, and the frame
processed next is always the newest. ``submit(item, block=True)`` instead waits for the slot
to be free: nothing is dropped (offline playback "as fast as possible").

MediaPipe releases the GIL while its graph runs, so a thread suffices to keep the executor
responsive; the per-frame Python work in the thread is small (colour conversion, mapping).

With ``finish`` the work is split over two threads: ``process`` (the detector) in the first,
``finish`` (the camera-motion estimate, which needs the frame's keypoints) on its result in a
second one, so that the next frame is detected while the last one is finished. The results
still come out in the order of the items, at most one result waits between the two threads
(the detector thread waits for the hand-off to be free, and meanwhile newer frames replace
the one in the input slot, counted in ``dropped`` as before), and ``seconds`` is the time
spent in both calls, without the waits.

:class:`SourceFeeder` reads a :class:`~mocap_keypoints.sources.FrameSource` in a second thread
and submits its frames: paced at the source's frame rate (``realtime``: a video then behaves
like a camera and drops frames the detector cannot keep up with), or as fast as the worker
takes them (no drops). Live sources (cameras) are never paced and always drop.
"""

from __future__ import annotations

import threading
import time
from typing import Any, Callable, Generic, Optional, TypeVar

T = TypeVar('T')
R = TypeVar('R')

_EMPTY = object()


class LatestWorker(Generic[T, R]):
    """Calls ``process(item)`` in its own thread on the newest submitted item and hands
    ``(item, result, error, seconds)`` to ``on_result`` (in the worker thread; ``error`` is the
    exception ``process`` raised, or None)."""

    def __init__(self, process: Callable[[T], R],
                 on_result: Callable[[T, Optional[R], Optional[BaseException], float], None],
                 name: str = 'detector', finish: Optional[Callable[[R], R]] = None,
                 finish_name: str = 'finish') -> None:
        self._process = process
        self._finish = finish
        self._on_result = on_result
        self._cond = threading.Condition()
        self._slot: Any = _EMPTY
        self._handoff: Any = _EMPTY     # (item, result, error, seconds) for the finish thread
        self._busy = False
        self._finishing = False
        self._stop = False
        self.submitted = 0
        self.dropped = 0
        self.processed = 0
        self.failed = 0
        self.callback_errors = 0
        self.callback_error: Optional[BaseException] = None
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._finish_thread = (threading.Thread(target=self._run_finish, name=finish_name,
                                                daemon=True) if finish is not None else None)

    def start(self) -> 'LatestWorker':
        self._thread.start()
        if self._finish_thread is not None:
            self._finish_thread.start()
        return self

    def submit(self, item: T, block: bool = False, timeout: Optional[float] = None) -> int:
        """Offer ``item``; returns the number of items dropped by this call (0 or 1).

        ``block=False``: replace a waiting item (dropped). ``block=True``: wait (up to
        ``timeout`` s) until the slot is free; on timeout the waiting item is dropped."""
        with self._cond:
            if self._stop:
                return 0
            if block:
                self._cond.wait_for(lambda: self._slot is _EMPTY or self._stop, timeout)
            dropped = 0 if self._slot is _EMPTY else 1
            self._slot = item
            self.submitted += 1
            self.dropped += dropped
            self._cond.notify_all()
            return dropped

    def _idle(self) -> bool:
        return (self._slot is _EMPTY and not self._busy and self._handoff is _EMPTY
                and not self._finishing)

    @property
    def idle(self) -> bool:
        """Nothing waiting and nothing being processed or finished."""
        with self._cond:
            return self._idle()

    def wait_free(self, timeout: Optional[float] = None) -> bool:
        """Wait until no item is waiting (the next submit drops nothing) or the worker stops."""
        with self._cond:
            return self._cond.wait_for(lambda: self._slot is _EMPTY or self._stop, timeout)

    def wait_idle(self, timeout: Optional[float] = None) -> bool:
        """Wait until nothing waits or is processed; False on timeout or once stopped with
        work left."""
        with self._cond:
            self._cond.wait_for(lambda: self._idle() or self._stop, timeout)
            return self._idle()

    @property
    def running(self) -> bool:
        """Whether a thread is still alive (e.g. after :meth:`stop` timed out)."""
        return self._thread.is_alive() or (self._finish_thread is not None
                                           and self._finish_thread.is_alive())

    def stop(self, timeout: Optional[float] = 5.0) -> None:
        """Stop after the items in progress (waiting items are discarded); waits up to
        ``timeout`` s for each thread (None: until it ends)."""
        with self._cond:
            self._stop = True
            self._slot = self._handoff = _EMPTY
            self._cond.notify_all()
        for thread in (self._thread, self._finish_thread):
            if thread is not None and thread.is_alive() and \
                    threading.current_thread() is not thread:
                thread.join(timeout)

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._slot is not _EMPTY or self._stop)
                if self._stop:
                    self._busy = False
                    self._cond.notify_all()
                    return
                item, self._slot = self._slot, _EMPTY
                self._busy = True
                self._cond.notify_all()
            t0 = time.perf_counter()
            result, error = None, None
            try:
                result = self._process(item)
            except Exception as exc:  # noqa: BLE001 - reported, never kills the thread
                error = exc
            seconds = time.perf_counter() - t0
            if self._finish is None:
                self._deliver(item, result, error, seconds)
                continue
            with self._cond:  # hand over in order; wait while the last one is still there
                self._cond.wait_for(lambda: self._handoff is _EMPTY or self._stop)
                self._busy = False
                if not self._stop:
                    self._handoff = (item, result, error, seconds)
                self._cond.notify_all()

    def _run_finish(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._handoff is not _EMPTY or self._stop)
                if self._stop:
                    self._finishing = False
                    self._cond.notify_all()
                    return
                (item, result, error, seconds), self._handoff = self._handoff, _EMPTY
                self._finishing = True
                self._cond.notify_all()
            if error is None:
                t0 = time.perf_counter()
                try:
                    result = self._finish(result)
                except Exception as exc:  # noqa: BLE001 - reported, never kills the thread
                    result, error = None, exc
                seconds += time.perf_counter() - t0
            self._deliver(item, result, error, seconds)

    def _deliver(self, item, result, error, seconds: float) -> None:
        """Hand one result to ``on_result`` and count it (in the last thread of the two). An
        exception of ``on_result`` is counted in ``callback_errors`` (the last one kept in
        ``callback_error``): the thread goes on."""
        try:
            self._on_result(item, result, error, seconds)
        except Exception as exc:  # noqa: BLE001 - a failing consumer never stops the worker
            self.callback_errors += 1
            self.callback_error = exc
        finally:
            with self._cond:
                if self._finish is None:
                    self._busy = False
                else:
                    self._finishing = False
                if error is None:
                    self.processed += 1
                else:
                    self.failed += 1
                self._cond.notify_all()


class SourceFeeder:
    """Reads ``source`` in a thread and submits each frame to ``worker``.

    Args:
        realtime: pace frames by their stamps (the source's frame rate) and drop what the
            worker cannot take; False: no pacing, wait for the worker, drop nothing.
            Live sources are never paced and always drop.
        on_frame: called for every frame read (input statistics), in the feeder thread.
        on_end: called once when the source ends (``reason``) or fails (``error`` set).
    """

    def __init__(self, source, worker: LatestWorker, realtime: bool = True,
                 on_frame: Optional[Callable[[Any], None]] = None,
                 on_end: Optional[Callable[[str, Optional[BaseException]], None]] = None,
                 ) -> None:
        self.source = source
        self.worker = worker
        self.live = bool(getattr(source, 'live', False))
        self.realtime = realtime and not self.live
        self.drop = self.live or realtime
        self.on_frame = on_frame
        self.on_end = on_end
        self.stop_event = threading.Event()
        self.finished = threading.Event()
        self.frames = 0
        self.late = 0  # paced frames that were already late when read
        self._thread = threading.Thread(target=self._run, name='source', daemon=True)

    def start(self) -> 'SourceFeeder':
        self._thread.start()
        return self

    def stop(self, timeout: float = 5.0) -> None:
        self.stop_event.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)

    def _run(self) -> None:
        reason, error = '', None
        t0_mono: Optional[float] = None
        stamp0 = 0
        try:
            for frame in self.source:
                if self.stop_event.is_set():
                    reason = 'stopped'
                    break
                if self.realtime:
                    if t0_mono is None:
                        t0_mono, stamp0 = time.monotonic(), frame.stamp_ns
                    delay = t0_mono + (frame.stamp_ns - stamp0) * 1e-9 - time.monotonic()
                    if delay > 0:
                        if self.stop_event.wait(delay):
                            reason = 'stopped'
                            break
                    elif delay < -0.5 / max(self.source.fps, 1e-3):
                        self.late += 1
                self.frames += 1
                if self.on_frame is not None:
                    self.on_frame(frame)
                if self.drop:
                    self.worker.submit(frame)
                else:  # wait for a free slot (this thread is the only producer)
                    while not self.worker.wait_free(0.2):
                        if self.stop_event.is_set():
                            break
                    self.worker.submit(frame)
            else:
                reason = getattr(self.source, 'ended_reason', '') or 'source ended'
        except Exception as exc:  # noqa: BLE001 - a failing source ends the stream, reported
            error = exc
            reason = str(exc)
        finally:
            self.finished.set()
            if self.on_end is not None:
                self.on_end(reason, error)
