"""Frame sources of the keypoint node (no ROS imports): a camera, a video file, a directory of
images, a directory of OpenPose JSON files.

Every source is an iterable of :class:`Frame` objects. A frame unpacks like the pair
``stamp_ns, image = frame`` (``image`` is an (H, W, 3) uint8 BGR array) and also carries its
index, a name for messages (file name or frame number) and, for a frame that could not be
read, ``error`` (the reason; ``image`` is then None) instead of raising: one bad frame never
ends a stream. A source that cannot be opened at all raises :class:`SourceError` (a clear
message naming the device or file) from its constructor.

Stamps (integer nanoseconds):
  * camera: the clock when the frame was grabbed;
  * video: ``start_ns + round(index * 1e9 / fps)`` with the file's own frame rate (or the
    ``fps`` given), ``index`` counting on across loops, so stamps never go backwards;
  * image and OpenPose directories: the same with ``fps`` (default 30).
``start_ns`` defaults to the clock when the first frame is read.
"""

from __future__ import annotations

import math
import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, List, Optional, Tuple

import numpy as np

#: File name endings read as images (what OpenCV's imread decodes here).
IMAGE_EXTENSIONS: Tuple[str, ...] = ('.png', '.jpg', '.jpeg', '.bmp', '.tif', '.tiff',
                                     '.webp', '.ppm', '.pgm', '.pnm')
#: Smallest image side accepted (BlazePose works on 256 x 256 crops; tiny images are noise).
MIN_IMAGE_SIDE = 16

SOURCE_KINDS: Tuple[str, ...] = ('camera', 'video', 'images', 'topic', 'openpose_json')


class SourceError(RuntimeError):
    """A source that cannot be opened or that stopped delivering frames for good."""


@dataclass
class Frame:
    """One input frame. ``stamp_ns, image = frame`` unpacks the stamp and the BGR image.

    Exactly one of ``image``, ``keypoints`` (ready-made (P, 23, 3) detections, OpenPose
    source), ``decode`` (a callable returning the image, run in the detector thread: image
    topics) or ``error`` (why the frame is unusable) is the payload.
    """

    stamp_ns: int
    image: Optional[np.ndarray] = None
    index: int = 0
    name: str = ''
    error: Optional[str] = None
    keypoints: Optional[np.ndarray] = None
    decode: Optional[Callable[[], np.ndarray]] = field(default=None, repr=False)
    frame_id: str = ''  # the camera frame of an image message ('' = the node's frame_id)

    def __iter__(self):
        yield self.stamp_ns
        yield self.image


def check_image(image, name: str = 'frame') -> np.ndarray:
    """Validate and normalise an image to (H, W, 3) uint8 BGR (gray and BGRA are converted).

    Raises ValueError with the reason for None, empty, non-uint8, tiny or non-finite images.
    """
    if image is None:
        raise ValueError(f'{name}: empty frame (no image data)')
    img = np.asarray(image)
    if img.size == 0:
        raise ValueError(f'{name}: empty frame (size {img.shape})')
    if img.dtype != np.uint8:
        raise ValueError(f'{name}: unsupported pixel type {img.dtype} (need 8-bit)')
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = np.repeat(img, 3, axis=2)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f'{name}: unsupported image shape {img.shape} (need H x W x 3 BGR)')
    if min(img.shape[:2]) < MIN_IMAGE_SIDE:
        raise ValueError(f'{name}: image too small ({img.shape[1]}x{img.shape[0]}, '
                         f'need at least {MIN_IMAGE_SIDE} px per side)')
    return np.ascontiguousarray(img)


def _natural_key(path: Path):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r'(\d+)', path.name)]


class FrameSource:
    """Base class: ``kind``, ``description``, ``fps`` (nominal rate, 0 = unknown), ``live``
    (frames arrive on their own schedule: the consumer must keep up or drop), iteration and
    ``close()``."""

    kind = ''
    live = False

    def __init__(self, clock_ns: Callable[[], int] = time.time_ns,
                 start_ns: Optional[int] = None) -> None:
        self.clock_ns = clock_ns
        self.start_ns = start_ns
        self.fps = 0.0
        self.description = ''
        self.frames_read = 0
        self.frames_bad = 0

    def _stamp(self, index: int) -> int:
        if self.start_ns is None:
            self.start_ns = int(self.clock_ns())
        return int(self.start_ns + round(index * 1e9 / self.fps))

    def __iter__(self) -> Iterator[Frame]:
        raise NotImplementedError

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class VideoSource(FrameSource):
    """A video file read with OpenCV (FFmpeg backend).

    Args:
        path: the file.
        fps: stamp rate; 0 = the file's own frame rate (30 if the file has none).
        loop: restart at the end (indices and stamps continue).
        max_bad_frames: consecutive undecodable frames before the video counts as ended.

    Raises SourceError when the file does not exist, OpenCV cannot open it, or its first
    frame cannot be decoded.
    """

    kind = 'video'

    def __init__(self, path, fps: float = 0.0, loop: bool = False, max_bad_frames: int = 25,
                 **kw) -> None:
        super().__init__(**kw)
        import cv2

        self.path = Path(path)
        if not self.path.is_file():
            raise SourceError(f'video file not found: {self.path}')
        if not os.access(self.path, os.R_OK):
            raise SourceError(f'video file not readable (permission denied): {self.path}')
        self._cv2 = cv2
        self.cap = cv2.VideoCapture(str(self.path))
        if not self.cap.isOpened():
            raise SourceError(f'cannot open video file {self.path} (not a video OpenCV can '
                              'read, or a corrupt file)')
        ok, first = self.cap.read()
        if not ok or first is None or first.size == 0:
            self.cap.release()
            raise SourceError(f'cannot decode any frame of video file {self.path}')
        self._first = first
        self.loop = loop
        self.max_bad_frames = max(1, int(max_bad_frames))
        self.file_fps = float(self.cap.get(cv2.CAP_PROP_FPS) or 0.0)
        if not math.isfinite(self.file_fps) or self.file_fps <= 0 or self.file_fps > 1000:
            self.file_fps = 0.0
        self.fps = float(fps) if fps and fps > 0 else (self.file_fps or 30.0)
        self.frame_count = int(self.cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        self.width = int(first.shape[1])
        self.height = int(first.shape[0])
        self.ended_reason = ''
        self.description = (f'video {self.path} ({self.width}x{self.height}, '
                            f'{self.frame_count} frames, {self.fps:.3f} fps'
                            f'{", looping" if loop else ""})')

    def __iter__(self) -> Iterator[Frame]:
        index = 0
        while True:
            pos = 0
            bad_run = 0
            while True:
                if self._first is not None:
                    ok, img = True, self._first
                    self._first = None
                else:
                    ok, img = self.cap.read()
                if ok and img is not None and img.size > 0:
                    bad_run = 0
                    self.frames_read += 1
                    yield Frame(self._stamp(index), img, index, f'frame {pos}')
                    index += 1
                    pos += 1
                    continue
                # No frame: the end, or an undecodable frame in the middle of the file.
                if self.frame_count and pos < self.frame_count - 1 and \
                        bad_run < self.max_bad_frames:
                    bad_run += 1
                    self.frames_bad += 1
                    yield Frame(self._stamp(index), None, index, f'frame {pos}',
                                error=f'{self.path.name}: cannot decode frame {pos} of '
                                      f'{self.frame_count}; skipping it')
                    index += 1
                    pos += 1
                    self.cap.set(self._cv2.CAP_PROP_POS_FRAMES, pos)
                    continue
                break
            self.ended_reason = (f'video ended after {pos} frames'
                                 + (f' ({bad_run} undecodable at the end)' if bad_run else ''))
            if not self.loop or pos == 0:
                return
            self.cap.set(self._cv2.CAP_PROP_POS_FRAMES, 0)
            if int(self.cap.get(self._cv2.CAP_PROP_POS_FRAMES) or 0) != 0:
                self.cap.release()  # some containers cannot seek: reopen
                self.cap = self._cv2.VideoCapture(str(self.path))

    def close(self) -> None:
        self.cap.release()


class ImageDirectorySource(FrameSource):
    """The images of a directory (:data:`IMAGE_EXTENSIONS`), in natural name order
    (``img2`` before ``img10``). An unreadable, corrupt, empty or tiny file gives a frame with
    ``error`` naming the file. Raises SourceError for a missing directory or one without
    images."""

    kind = 'images'

    def __init__(self, path, fps: float = 30.0, loop: bool = False, **kw) -> None:
        super().__init__(**kw)
        self.path = Path(path)
        if not self.path.is_dir():
            raise SourceError(f'image directory not found: {self.path}')
        self.files: List[Path] = sorted(
            (f for f in self.path.iterdir() if f.suffix.lower() in IMAGE_EXTENSIONS
             and f.is_file()), key=_natural_key)
        if not self.files:
            raise SourceError(f'no image files ({", ".join(IMAGE_EXTENSIONS)}) in {self.path}')
        self.fps = float(fps) if fps and fps > 0 else 30.0
        self.loop = loop
        self.ended_reason = ''
        self.description = (f'images {self.path} ({len(self.files)} files at {self.fps:g} fps'
                            f'{", looping" if loop else ""})')

    def read(self, path: Path) -> np.ndarray:
        """Read one image file -> BGR; raises ValueError naming the file."""
        import cv2

        try:
            data = np.fromfile(str(path), dtype=np.uint8)
        except OSError as exc:
            raise ValueError(f'{path}: cannot read file ({exc.strerror or exc})') from None
        if data.size == 0:
            raise ValueError(f'{path}: empty file')
        img = cv2.imdecode(data, cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f'{path}: not a readable image (corrupt or unsupported format)')
        return check_image(img, str(path))

    def __iter__(self) -> Iterator[Frame]:
        index = 0
        while True:
            for f in self.files:
                try:
                    img = self.read(f)
                except ValueError as exc:
                    self.frames_bad += 1
                    yield Frame(self._stamp(index), None, index, f.name, error=str(exc))
                else:
                    self.frames_read += 1
                    yield Frame(self._stamp(index), img, index, f.name)
                index += 1
            if not self.loop:
                self.ended_reason = f'all {len(self.files)} images read'
                return


class OpenPoseSource(FrameSource):
    """A directory of OpenPose JSON files (one per frame, see :mod:`.openpose`); frames carry
    ``keypoints`` (P, 23, 3) instead of an image. A malformed file gives a frame whose
    ``error`` names the file. Raises SourceError for a missing or empty directory."""

    kind = 'openpose_json'

    def __init__(self, path, fps: float = 30.0, loop: bool = False, **kw) -> None:
        super().__init__(**kw)
        from mocap_core.data.openpose import list_openpose_files

        self.path = Path(path)
        try:
            self.files = list_openpose_files(self.path)
        except FileNotFoundError as exc:
            raise SourceError(str(exc)) from None
        self.fps = float(fps) if fps and fps > 0 else 30.0
        self.loop = loop
        self.ended_reason = ''
        self.description = (f'OpenPose JSON {self.path} ({len(self.files)} frames at '
                            f'{self.fps:g} fps{", looping" if loop else ""})')

    def __iter__(self) -> Iterator[Frame]:
        from mocap_core.data.openpose import OpenPoseError, read_openpose_file

        index = 0
        while True:
            for _, f in self.files:
                try:
                    people = read_openpose_file(f)
                except OpenPoseError as exc:
                    self.frames_bad += 1
                    yield Frame(self._stamp(index), None, index, f.name, error=str(exc))
                else:
                    self.frames_read += 1
                    yield Frame(self._stamp(index), None, index, f.name, keypoints=people)
                index += 1
            if not self.loop:
                self.ended_reason = f'all {len(self.files)} OpenPose files read'
                return


def parse_device(device) -> int | str:
    """``'0'`` -> 0 (a camera index); anything else (``/dev/video2``, a URL) stays a string."""
    text = str(device).strip()
    return int(text) if re.fullmatch(r'\d+', text) else text


class CameraSource(FrameSource):
    """A camera opened with OpenCV (V4L2 on Linux): a device index (``0``), a device path
    (``/dev/video0``) or a stream URL.

    Frames are stamped with the clock when grabbed. ``width``, ``height``, ``fps`` > 0 are
    requested from the driver (it may choose others; the frames say what it delivers).
    Raises SourceError when the device does not exist or cannot be opened, or delivers no
    frame within ``open_timeout_s``. While running, a failed grab gives an error frame;
    ``max_failures`` failures in a row raise SourceError (camera unplugged).
    """

    kind = 'camera'
    live = True

    def __init__(self, device='0', width: int = 0, height: int = 0, fps: float = 0.0,
                 max_failures: int = 30, **kw) -> None:
        super().__init__(**kw)
        import cv2

        self._cv2 = cv2
        self.device = parse_device(device)
        if isinstance(self.device, str) and self.device.startswith('/dev/') and \
                not os.path.exists(self.device):
            raise SourceError(f'camera device not found: {self.device}')
        self.cap = cv2.VideoCapture(self.device)
        if not self.cap.isOpened():
            raise SourceError(f'camera not found or cannot be opened: device {device!r} '
                              '(check the index or path, permissions, and that no other '
                              'program holds it)')
        self.cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the driver keeps no stale frames
        if width > 0:
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, int(width))
        if height > 0:
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, int(height))
        if fps > 0:
            self.cap.set(cv2.CAP_PROP_FPS, float(fps))
        self.fps = float(self.cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.max_failures = max(1, int(max_failures))
        self.description = (f'camera {device} ({int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH))}x'
                            f'{int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT))}, '
                            f'{self.fps:g} fps requested by the driver)')
        self.ended_reason = ''

    def __iter__(self) -> Iterator[Frame]:
        index = 0
        failures = 0
        while True:
            ok = self.cap.grab()
            stamp = int(self.clock_ns())
            img = None
            if ok:
                ok, img = self.cap.retrieve()
            if ok and img is not None and img.size > 0:
                failures = 0
                self.frames_read += 1
                yield Frame(stamp, img, index, f'frame {index}')
            else:
                failures += 1
                self.frames_bad += 1
                if failures >= self.max_failures:
                    raise SourceError(f'camera {self.device!r} delivered no frame in '
                                      f'{failures} tries (unplugged?)')
                yield Frame(stamp, None, index, f'frame {index}',
                            error=f'camera {self.device!r}: failed to grab frame {index}')
                time.sleep(0.01)
            index += 1

    def close(self) -> None:
        self.cap.release()


def resolve_kind(source: str, path: str) -> str:
    """The source kind for ``source`` ('auto' guesses from ``path``: empty -> camera, a file
    -> video, a directory with JSON files -> openpose_json, other directories -> images)."""
    source = (source or 'auto').strip()
    if source != 'auto':
        if source not in SOURCE_KINDS:
            raise ValueError(f'unknown source {source!r}; use one of auto, '
                             f'{", ".join(SOURCE_KINDS)}')
        return source
    if not path:
        return 'camera'
    p = Path(path)
    if p.is_file():
        return 'video'
    if p.is_dir():
        if any(p.glob('*.json')):
            return 'openpose_json'
        return 'images'
    raise SourceError(f'path not found: {p} (source auto: give a video file, an image or '
                      'OpenPose JSON directory, or set source)')


def open_source(kind: str, path: str = '', device: str = '0', fps: float = 0.0,
                loop: bool = False, width: int = 0, height: int = 0,
                clock_ns: Callable[[], int] = time.time_ns) -> FrameSource:
    """Open a source of ``kind`` (see :data:`SOURCE_KINDS`, except 'topic', which the node
    subscribes to). Raises SourceError with a clear message when it cannot be opened."""
    if kind == 'camera':
        return CameraSource(device, width=width, height=height, fps=fps, clock_ns=clock_ns)
    if kind in ('video', 'images', 'openpose_json') and not path:
        raise SourceError(f'source {kind} needs the path parameter')
    if kind == 'video':
        return VideoSource(path, fps=fps, loop=loop, clock_ns=clock_ns)
    if kind == 'images':
        return ImageDirectorySource(path, fps=fps, loop=loop, clock_ns=clock_ns)
    if kind == 'openpose_json':
        return OpenPoseSource(path, fps=fps, loop=loop, clock_ns=clock_ns)
    raise ValueError(f'no frame source for kind {kind!r}')

