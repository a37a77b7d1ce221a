import cv2
import numpy as np
import pytest

from mocap_core.camera import CameraCalibration, CameraIntrinsics
from mocap_core.skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS
from mocap_keypoints.intrinsics import (FrameIntrinsics, IntrinsicsProvider,
                                        undistort_keypoints)
from mocap_keypoints.pipeline import FrameProcessor, draw_keypoints, select_persons
from mocap_keypoints.sources import Frame

K720 = CameraIntrinsics(1280, 720, 1000.0, 1010.0, 639.5, 359.5)


def _calib(intr=K720, model='plumb_bob', dist=()):
    return CameraCalibration(intr, model, tuple(dist), 'cam')


# --- intrinsics --------------------------------------------------------------------------------
def test_provider_prefers_file_then_camera_info_then_approximation():
    prov = IntrinsicsProvider(None, horizontal_fov_deg=90.0)
    fi, note = prov.for_image(640, 360)
    assert fi.approximate and fi.intrinsics.fx == pytest.approx(320.0)
    assert 'approximating intrinsics from image size 640x360' in note
    assert prov.for_image(640, 360)[1] is None          # no repeated note
    assert prov.update_camera_info(_calib()) and not prov.update_camera_info(_calib())
    fi, note = prov.for_image(640, 360)                  # half size: scaled
    assert fi.source == 'camera_info' and 'scaled' in note
    assert (fi.intrinsics.fx, fi.intrinsics.fy) == pytest.approx((500.0, 505.0))
    assert (fi.intrinsics.cx, fi.intrinsics.cy) == pytest.approx((319.5, 179.5))
    fi, _ = prov.for_image(1280, 720)
    assert fi.intrinsics == K720
    filed = IntrinsicsProvider(_calib(CameraIntrinsics(640, 360, 400.0, 400.0, 320.0, 180.0)),
                               calibration_label='cam.yaml')
    filed.update_camera_info(_calib())
    fi, note = filed.for_image(640, 360)
    assert fi.source == 'calibration_file' and fi.intrinsics.fx == 400.0 and 'cam.yaml' in note


def test_provider_rejects_a_calibration_of_another_aspect_ratio():
    prov = IntrinsicsProvider(_calib(), horizontal_fov_deg=60.0, calibration_label='c.yaml')
    fi, note = prov.for_image(640, 480)
    assert fi.approximate and 'another aspect ratio' in note and '1280x720' in note


def test_undistort_keypoints_matches_the_pinhole_projection():
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(-0.6, 0.6, 23), rng.uniform(-0.4, 0.4, 23),
                           np.full(23, 1.0)])
    K = K720.K
    ideal = (pts[:, :2] / pts[:, 2:]) * [K720.fx, K720.fy] + [K720.cx, K720.cy]
    for model, dist in (('plumb_bob', [-0.25, 0.08, 0.001, -0.0005, -0.01]),
                        ('equidistant', [0.05, -0.01, 0.002, -0.001])):
        if model == 'plumb_bob':
            raw, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, np.array(dist))
        else:
            raw, _ = cv2.fisheye.projectPoints(pts.reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                               K, np.array(dist))
        kp = np.concatenate([raw.reshape(-1, 2), np.full((23, 1), 0.9)], axis=1)[None]
        kp[0, 5] = 0.0  # unseen stays unseen
        fi = FrameIntrinsics(K720, 'calibration_file', '', model, tuple(dist))
        und = undistort_keypoints(kp, fi)
        assert np.abs(raw.reshape(-1, 2) - ideal).max() > 5   # the distortion is real
        seen = np.arange(23) != 5
        np.testing.assert_allclose(und[0, seen, :2], ideal[seen], atol=0.05)
        assert np.all(und[0, 5] == 0) and np.all(und[..., 2][0, seen] == 0.9)


# --- frame processing --------------------------------------------------------------------------
class FakeDetector:
    name = 'fake'

    def __init__(self, people):
        self.people = people
        self.calls = 0

    def detect(self, image):
        self.calls += 1
        return self.people

    def reset(self):
        pass

    def close(self):
        pass


def _person(u=100.0, v=50.0, conf=0.9):
    p = np.zeros((1, NUM_KEYPOINTS, 3))
    p[0, :, 0] = u + np.arange(NUM_KEYPOINTS) * 5
    p[0, :, 1] = v + np.arange(NUM_KEYPOINTS) * 8
    p[0, :, 2] = conf
    return p


def test_processor_detects_and_fills_the_result():
    img = np.zeros((360, 640, 3), np.uint8)
    proc = FrameProcessor(FakeDetector(_person()), IntrinsicsProvider(), max_persons=2,
                          annotate=True)
    res = proc.process(Frame(123, img, 4, 'frame 4'))
    assert res.error is None and res.stamp_ns == 123 and res.person_found
    assert res.keypoints.shape == (2, NUM_KEYPOINTS, 3)
    np.testing.assert_array_equal(res.keypoints[0], _person()[0])
    assert np.all(res.keypoints[1] == 0)               # padding person: not seen
    assert res.image_size == (640, 360) and res.intrinsics.approximate
    assert any('approximating' in n for n in res.notes)
    assert res.annotated.shape == img.shape and res.annotated.any() and not img.any()


def test_processor_no_person_gives_zero_confidences():
    proc = FrameProcessor(FakeDetector(np.zeros((0, NUM_KEYPOINTS, 3))), IntrinsicsProvider())
    res = proc.process(Frame(1, np.zeros((100, 100, 3), np.uint8)))
    assert res.error is None and not res.person_found
    assert res.keypoints.shape == (1, NUM_KEYPOINTS, 3) and not res.keypoints.any()


def test_processor_with_tracker_gives_stable_ids_in_shuffled_rows():
    from mocap_core.tracking import PersonTracker, TrackerParams

    class Shuffling(FakeDetector):
        def detect(self, image):
            self.calls += 1
            a, b = _person(100.0 + 4 * self.calls), _person(400.0 - 4 * self.calls, conf=0.8)
            return np.concatenate([a, b] if self.calls % 2 else [b, a])

    proc = FrameProcessor(Shuffling(None), IntrinsicsProvider(), max_persons=4,
                          tracker=PersonTracker(TrackerParams(birth_frames=2)), annotate=True)
    img = np.zeros((360, 640, 3), np.uint8)
    first = proc.process(Frame(0, img, 0))
    assert first.keypoints.shape == (1, NUM_KEYPOINTS, 3) and first.ids.tolist() == [0]
    assert not first.person_found                       # not confirmed yet: nobody published
    by_id = {}
    for k in range(1, 12):
        res = proc.process(Frame(k * 33_000_000, img, k))
        assert sorted(res.ids.tolist()) == [1, 2]
        for row, i in enumerate(res.ids):
            by_id.setdefault(int(i), []).append(res.keypoints[row, 0, 0])
    # each id stays with one person: one moves right, the other left
    moves = {i: np.diff(u) for i, u in by_id.items()}
    assert {tuple(np.sign(m).astype(int)) for m in moves.values()} == {(1,) * 10, (-1,) * 10}
    # a stream restart (stamps back) forgets everyone
    res = proc.process(Frame(0, img, 99))
    assert res.ids.tolist() == [0]


def test_processor_reports_bad_frames_without_raising():
    det = FakeDetector(_person())
    proc = FrameProcessor(det, IntrinsicsProvider())

    def broken():
        raise ValueError("unsupported image encoding '32FC1'")

    cases = [Frame(1, None, 0, 'a.png', error='a.png: empty file'),
             Frame(2, None, 1, 'topic image 1', decode=broken),
             Frame(3, np.zeros((5, 5, 3), np.uint8), 2, 'tiny'),
             Frame(4, None, 3, 'nothing')]
    reasons = [proc.process(f).error for f in cases]
    assert reasons[0] == 'a.png: empty file'
    assert '32FC1' in reasons[1] and 'too small' in reasons[2] and 'empty frame' in reasons[3]
    assert det.calls == 0


def test_processor_decodes_lazily_and_notes_size_changes():
    proc = FrameProcessor(FakeDetector(_person()), IntrinsicsProvider())
    r1 = proc.process(Frame(1, None, 0, 'm0', decode=lambda: np.zeros((360, 640, 3), np.uint8)))
    r2 = proc.process(Frame(2, np.zeros((480, 640, 3), np.uint8), 1, 'm1'))
    assert r1.image_size == (640, 360) and r2.image_size == (640, 480)
    assert any('size changed from 640x360 to 640x480' in n for n in r2.notes)


def test_processor_openpose_frames_and_undistortion():
    dist = (-0.2, 0.05, 0.0, 0.0, 0.0)
    prov = IntrinsicsProvider(_calib(dist=dist))
    proc = FrameProcessor(None, prov, fixed_size=(1280, 720))
    people = _person(100, 50)  # far from the centre: a visible correction
    res = proc.process(Frame(7, None, 0, 'x.json', keypoints=people))
    assert res.intrinsics.source == 'calibration_file'
    # Undistortion moves points away from the centre for barrel distortion (k1 < 0).
    r_in = np.hypot(people[0, :, 0] - 639.5, people[0, :, 1] - 359.5)
    r_out = np.hypot(res.keypoints[0, :, 0] - 639.5, res.keypoints[0, :, 1] - 359.5)
    assert np.all(r_out >= r_in - 1e-6) and np.any(r_out > r_in + 1)
    raw = FrameProcessor(None, prov, fixed_size=(1280, 720), undistort=False)
    np.testing.assert_array_equal(raw.process(Frame(8, None, 0, 'x', keypoints=people))
                                  .keypoints, people)
    unsized = FrameProcessor(None, prov)
    assert 'no image size' in unsized.process(Frame(9, None, 0, 'x', keypoints=people)).error


def test_select_persons_orders_by_confidence():
    a, b = _person(conf=0.3), _person(conf=0.8)
    out = select_persons(np.concatenate([a, b]), 1)
    np.testing.assert_array_equal(out[0], b[0])


def test_draw_keypoints_draws_bones_and_points():
    img = np.zeros((200, 200, 3), np.uint8)
    kp = np.zeros((1, NUM_KEYPOINTS, 3))
    i = KEYPOINT_INDEX
    kp[0, i['left_shoulder']] = (150, 50, 1.0)
    kp[0, i['left_elbow']] = (150, 150, 1.0)
    kp[0, i['right_shoulder']] = (50, 50, 0.2)    # below the threshold: not drawn
    out = draw_keypoints(img, kp, threshold=0.5, text='hi')
    assert out[100, 150].any()                      # the bone between shoulder and elbow
    assert not out[50, 50].any() and not img.any()


def test_processor_measures_the_camera_translation_over_a_floor_it_is_given():
    """The floor handed over (as the node does from the physics floor topic) reaches the
    camera-motion estimate: a camera walking over a textured floor gets its path in metres;
    an implausible floor is noted and ignored."""
    from mocap_core.camera_motion import CameraMotionParams
    from mocap_core.rotations import axis_angle_to_matrix
    from mocap_core.testing import textured_floor_view

    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 319.5, 239.5)
    prov = IntrinsicsProvider(_calib(intr))
    proc = FrameProcessor(FakeDetector(np.zeros((0, NUM_KEYPOINTS, 3))), prov,
                          camera_motion=CameraMotionParams())
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    R_wc = axis_angle_to_matrix(np.array([0.0, np.radians(25.0), 0.0])) @ base
    res = []
    for i in range(20):
        if i == 3:
            proc.set_floor(np.array([0.0, 0.0, 1.0]), 500.0, 0.0)      # not plausible
        if i == 5:
            proc.set_floor(R_wc.T @ np.array([0.0, 0.0, 1.0]), 1.5, 4 / 30)
        img = textured_floor_view(R_wc, [0.04 * i, 0.0, 1.5], intr.K)
        res.append(proc.process(Frame(int(i * 1e9 / 30), img, i, f'f{i}')))
    assert any('not plausible' in n for n in res[3].notes)
    cms = [r.camera_motion for r in res]
    assert not any(c.translation_known for c in cms[1:5])
    assert all(c.translation_known for c in cms[6:]), [c.frame_state for c in cms]
    step = cms[-1].position - cms[6].position       # 13 frames of 4 cm, along the optical z
    assert np.linalg.norm(step - R_wc.T @ [0.52, 0.0, 0.0]) < 0.03, step


def test_detect_and_finish_in_two_threads_give_what_process_gives():
    """The node's default (``finish_thread``): frames detected in one thread and finished
    (camera motion, annotation) in another, the next frame detected meanwhile, come out as
    the same results as one ``process`` call per frame: the two parts share no state. A
    failed frame passes through ``finish`` unchanged."""
    from mocap_core.camera_motion import CameraMotionParams
    from mocap_core.rotations import axis_angle_to_matrix
    from mocap_core.testing import textured_floor_view
    from mocap_keypoints.worker import LatestWorker

    intr = CameraIntrinsics(640, 480, 500.0, 500.0, 319.5, 239.5)
    base = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    frames = []
    for i in range(16):
        R_wc = axis_angle_to_matrix(np.array([0.0, np.radians(25.0), 0.01 * i])) @ base
        img = textured_floor_view(R_wc, [0.03 * i, 0.0, 1.5], intr.K)
        frames.append(Frame(int(i * 1e9 / 30), img, i, f'f{i}'))
    frames.insert(8, Frame(int(7.5e9 / 30), None, 99, 'broken', error='unreadable'))
    person = np.zeros((1, NUM_KEYPOINTS, 3))
    person[0, :, :2] = np.linspace(280, 360, NUM_KEYPOINTS)[:, None]
    person[0, :, 2] = 0.9

    def processor():
        return FrameProcessor(FakeDetector(person), IntrinsicsProvider(_calib(intr)),
                              camera_motion=CameraMotionParams(), annotate=True)

    one = processor()
    expected = [one.process(f) for f in frames]
    two = processor()
    got = []
    w = LatestWorker(two.detect, lambda f, r, e, s: got.append(r), finish=two.finish).start()
    for f in frames:
        w.submit(f, block=True)
    assert w.wait_idle(30.0)
    w.stop()
    assert [r.index for r in got] == [r.index for r in expected]
    assert got[8].error == 'unreadable' and got[8].camera_motion is None
    moving = 0
    for a, b in zip(got, expected):
        if b.error is not None:
            continue
        np.testing.assert_array_equal(a.keypoints, b.keypoints)
        # the drawing, without the top line's text (it carries the detector's time)
        np.testing.assert_array_equal(a.annotated[40:], b.annotated[40:])
        ca, cb = a.camera_motion, b.camera_motion
        assert (ca.state, ca.frame_state) == (cb.state, cb.frame_state)
        np.testing.assert_array_equal(ca.orientation, cb.orientation)
        np.testing.assert_array_equal(ca.angular_velocity, cb.angular_velocity)
        moving += ca.state != 'static'
    assert moving >= 10     # the camera turns: the estimates carry something to compare
