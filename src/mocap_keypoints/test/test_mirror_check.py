"""The mirror check (mocap_keypoints.mirror_check): a second detector reads the mirrored frame;
a person labelled as facing the camera whom that reading sees facing away is exchanged."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mocap_core.skeleton import KEYPOINT_INDEX, KEYPOINT_MIRROR, NUM_KEYPOINTS
from mocap_core.testing import upright_keypoints
from mocap_keypoints.facing import signed_width
from mocap_keypoints.mirror_check import (MirrorCheck, MirrorCheckParams, mirrored_back,
                                          same_person_distance)

REPO = Path(__file__).resolve().parents[3]
MIR = list(KEYPOINT_MIRROR)
W = 640


def _person(facing_camera: bool, cx: float = 320.0, height: float = 300.0) -> np.ndarray:
    """(23, 3) an upright person, labels facing the camera or away, slightly asymmetric (the
    left arm raised) so that a labelling and its exchange differ in more than the sign."""
    kp = upright_keypoints(facing_camera, cx=cx, top=60.0, height=height)
    kp[KEYPOINT_INDEX['left_wrist'], 1] = 30.0
    return kp


def _as_seen_mirrored(kp: np.ndarray) -> np.ndarray:
    """What a detector reading the mirrored image returns for the person ``kp`` read the
    same way (the inverse of mirrored_back)."""
    out = kp[MIR].copy()
    out[:, 0] = (W - 1) - out[:, 0]
    return out


class Scripted:
    """A detector returning set persons (in the mirrored image's pixels) frame after frame."""

    name = 'scripted'

    def __init__(self, frames):
        self.frames = list(frames)
        self.calls = self.resets = 0
        self.images = []

    def detect(self, image):
        self.images.append(image)
        self.calls += 1
        return self.frames[min(self.calls - 1, len(self.frames) - 1)]

    def reset(self):
        self.resets += 1

    def close(self):
        pass


def test_mirrored_back_undoes_the_mirror_and_the_labels():
    kp = _person(True)
    back = mirrored_back(_as_seen_mirrored(kp)[None], W)[0]
    np.testing.assert_allclose(back, kp)
    # the reading's belief survives the way back: a person read as facing the camera in the
    # mirrored image is read as facing it in the image, one read as facing away as facing away
    for facing in (True, False):
        there = _person(facing, cx=W - 1 - 320.0)
        assert (signed_width(mirrored_back(there[None], W)[0]) > 0) == facing


def test_same_person_distance_ignores_labels_and_tells_people_apart():
    a = _person(True)
    assert same_person_distance(a, a) == pytest.approx(0.0)
    assert same_person_distance(a, a[MIR]) == pytest.approx(0.0)
    assert same_person_distance(a, _person(True, cx=400.0)) > 0.2
    hidden = a.copy()
    hidden[:, 2] = 0.0
    assert same_person_distance(a, hidden) == np.inf


def test_check_exchanges_where_the_mirrored_reading_faces_away():
    image = np.zeros((480, W, 3), np.uint8)
    image[:, :10] = 255                                   # the detector must see the mirror
    facing = _person(True)
    truth_away = facing[MIR]                              # the same points, labels away
    # frame 1: the mirrored reading sees the person facing away: exchanged
    # frame 2: it agrees with the main detector: kept
    # frame 3: it finds somebody else only: kept
    det = Scripted([_as_seen_mirrored(truth_away)[None], _as_seen_mirrored(facing)[None],
                    _as_seen_mirrored(_person(False, cx=100.0))[None]])
    check = MirrorCheck(lambda: det, MirrorCheckParams())
    out, ex = check.apply(image, facing[None])
    assert ex.tolist() == [True] and signed_width(out[0]) < 0
    np.testing.assert_array_equal(out[0], facing[MIR])
    assert det.images[0][0, -1, 0] == 255 and det.images[0][0, 0, 0] == 0   # flipped
    for _ in range(2):
        out, ex = check.apply(image, facing[None])
        assert not ex.any() and signed_width(out[0]) > 0
    s = check.stats
    assert (s.frames, s.read, s.candidates, s.matched, s.exchanged) == (3, 3, 3, 2, 1)
    assert len(s.times) == 3 and s.times.summary()['median'] >= 0


def test_check_leaves_people_facing_away_side_on_or_absent_alone():
    image = np.zeros((480, W, 3), np.uint8)
    away = _person(False)
    side = _person(True)
    for n in ('shoulder', 'hip'):
        side[KEYPOINT_INDEX[f'left_{n}'], 0] = side[KEYPOINT_INDEX[f'right_{n}'], 0] + 5.0
    for person in (away, side, np.zeros((NUM_KEYPOINTS, 3))):
        for every_frame in (False, True):
            det = Scripted([_as_seen_mirrored(person[MIR])[None]])
            check = MirrorCheck(lambda d=det: d, MirrorCheckParams(
                only_when_needed=not every_frame))
            assert MirrorCheckParams().only_when_needed is False   # every frame by default
            out, ex = check.apply(image, person[None])
            assert not ex.any() and out is not None
            assert check.stats.candidates == 0
            # nobody to check: the mirrored frame is read only when asked to read every frame
            assert det.calls == int(every_frame) == check.stats.read
    # after frames it skipped, the second detector starts afresh (its tracking is stale)
    facing = _person(True)
    det = Scripted([_as_seen_mirrored(facing)[None]])
    check = MirrorCheck(lambda: det, MirrorCheckParams(only_when_needed=True))
    for person in (facing, facing, away, away, facing):
        check.apply(image, person[None])
    assert (det.calls, det.resets, check.stats.read, check.stats.frames) == (3, 1, 3, 5)
    # nobody found in the mirrored frame: nothing to go by
    check = MirrorCheck(lambda: Scripted([np.zeros((0, NUM_KEYPOINTS, 3))]))
    assert not check.apply(image, _person(True)[None])[1].any()


def test_frame_processor_runs_the_mirror_check_and_survives_its_failure():
    from mocap_keypoints.intrinsics import IntrinsicsProvider
    from mocap_keypoints.pipeline import FrameProcessor
    from mocap_keypoints.sources import Frame

    facing = _person(True)
    main = Scripted([facing[None]])
    mirrored = Scripted([_as_seen_mirrored(facing[MIR])[None]])
    proc = FrameProcessor(main, IntrinsicsProvider(), max_persons=1,
                          mirror=MirrorCheck(lambda: mirrored))
    image = np.zeros((480, W, 3), np.uint8)
    res = proc.process(Frame(1, image, 0))
    assert res.exchanged.tolist() == [True] and signed_width(res.keypoints[0]) < 0
    # stamps jumping back restart the stream: the mirrored detector forgets its person too
    proc.process(Frame(10_000_000_000, image, 1))
    proc.process(Frame(1, image, 2))
    assert mirrored.resets == 1

    class Broken(Scripted):
        def detect(self, image):
            raise RuntimeError('model crashed')

    proc.mirror = MirrorCheck(lambda: Broken([]))
    res = proc.process(Frame(2_000_000_000, image, 3))
    assert res.error is None and proc.mirror_failures == 1
    assert signed_width(res.keypoints[0]) > 0 and 'mirror check failed' in res.notes[-1]


def test_mirror_check_leaves_the_real_taiji_performer_alone():
    """On the repository's real video (the performer faces the camera, the detector's labels
    are right) the mirrored reading agrees: nothing is exchanged, and the person is found in
    the mirrored frame nearly always."""
    import cv2

    from mocap_keypoints.detector import create_detector

    main = create_detector('blazepose', tracking=True)
    check = MirrorCheck(lambda: create_detector('blazepose', tracking=True))
    cap = cv2.VideoCapture(str(REPO / 'data' / 'video_example' / 'taiji_640x360.mp4'))
    try:
        while True:
            ok, image = cap.read()
            if not ok:
                break
            people = main.detect(image)
            if len(people):
                check.apply(image, people[:1])
    finally:
        cap.release()
        main.close()
        check.close()
    s = check.stats
    assert s.candidates >= 90 and s.matched >= 0.95 * s.candidates, s
    assert s.exchanged == 0, s
