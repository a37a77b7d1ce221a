"""The multi-person BlazePose detector (mocap_keypoints.multipose) on the committed clip: the
bundle builds offline from the wheel, one person comes out as the single-person detector
sees it, and two people side by side are both found, each where the single-person detector
finds them alone."""

import numpy as np
import pytest

from mocap_core.skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS
from mocap_keypoints.multipose import (BlazePoseMultiDetector, changed_outside, picture_range,
                                       pose_bundle)

BODY = [KEYPOINT_INDEX[n] for n in ('left_shoulder', 'right_shoulder', 'left_hip', 'right_hip',
                                    'left_knee', 'right_knee', 'left_ankle', 'right_ankle')]

SWAPPED = [BODY[i ^ 1] for i in range(len(BODY))]     # BODY is in (left, right) pairs


def test_bundle_is_built_from_the_wheel(tmp_path):
    import zipfile
    path = pose_bundle(tmp_path)
    assert path.parent == tmp_path and path.stat().st_size > 1_000_000
    with zipfile.ZipFile(path) as z:
        assert sorted(z.namelist()) == ['pose_detector.tflite', 'pose_landmarks_detector.tflite']
    assert pose_bundle(tmp_path) == path                  # cached


def _error_px(a, b):
    both = (a[:, BODY, 2] > 0.5) & (b[:, BODY, 2] > 0.5)
    d = np.linalg.norm(a[:, BODY, :2] - b[:, BODY, :2], axis=-1)
    return np.median(d[both]), both.mean()


def test_one_person_as_the_single_person_detector(clip_frames, clip_detections, fully_visible):
    single = np.concatenate(clip_detections[0])
    multi = []
    with BlazePoseMultiDetector(max_persons=4) as det:
        for f in clip_frames:
            got = det.detect(f.image)
            assert got.shape[1:] == (NUM_KEYPOINTS, 3) and len(got) <= 1
            multi.append(got[0] if len(got) else np.zeros((NUM_KEYPOINTS, 3)))
        # the clip's person is large and alone: tracked on the whole image, as the
        # single-person detector does, from the first frame to the end
        assert det.num_windows == 1 and det._windows[0].whole
        assert det.whole_switches == 0 and det.windows_opened == 1
    multi = np.array(multi)
    err, shared = _error_px(multi[fully_visible], single[fully_visible])
    assert shared > 0.85 and err < 6.0, (err, shared)


def test_a_lone_person_goes_back_to_a_window_when_somebody_comes(clip_frames, clip_detections):
    """The clip next to a grey half: one person, tracked on the whole image (threshold
    lowered to their size in the wider image); then their mirror image appears in the grey
    half: the lone person's landmarker goes back to a window, and both are found where the
    single-person detector sees them."""
    frames = clip_frames[::2][:45]
    single = np.concatenate(clip_detections[0])[::2][:45]
    w = frames[0].image.shape[1]
    whole, found = [], []
    with BlazePoseMultiDetector(max_persons=4, detection_interval=1,
                                whole_frame_min_height=0.15,
                                whole_frame_leave_height=0.1) as det:
        for k, (f, s) in enumerate(zip(frames, single)):
            other = np.full_like(f.image, 127) if k < 15 else f.image[:, ::-1]
            got = det.detect(np.concatenate([f.image, other], axis=1))
            whole.append(any(win.whole for win in det._windows))
            found.append(len(got))
            if k >= 15 and len(got) == 2 and s[BODY, 2].min() >= 0.5:
                left = got[np.argmin(got[:, BODY, 0].mean(axis=1))]
                assert np.median(np.abs(left[BODY, :2] - s[BODY, :2])) < 10.0
    assert all(whole[3:15]) and found[3:15] == [1] * 12, (whole, found)
    scan = len(BlazePoseMultiDetector.regions(2 * w, frames[0].image.shape[0]))
    assert not any(whole[15 + scan:]), whole
    assert np.mean(np.array(found[15 + scan:]) == 2) >= 0.8, found


@pytest.mark.parametrize('threads', [1, 2])
def test_two_people_side_by_side(clip_frames, clip_detections, threads):
    """The clip next to its mirror image: two people, each found where the single-person
    detector finds the person of its half (mirrored for the right half); the two windows'
    landmarkers one after the other or at once in two threads."""
    frames = clip_frames[::3][:30]
    single = np.concatenate(clip_detections[0])[::3][:30]
    w = frames[0].image.shape[1]
    found = []
    scan = len(BlazePoseMultiDetector.regions(2 * w, frames[0].image.shape[0]))
    with BlazePoseMultiDetector(max_persons=4, detection_interval=1, threads=threads) as det:
        for f, s in zip(frames, single):
            img = np.concatenate([f.image, f.image[:, ::-1]], axis=1)
            got = det.detect(img)
            found.append(len(got))
            if len(got) != 2 or s[BODY, 2].min() < 0.5:
                continue
            left = got[np.argmin(got[:, BODY, 0].mean(axis=1))]
            right = got[np.argmax(got[:, BODY, 0].mean(axis=1))]
            assert np.median(np.abs(left[BODY, :2] - s[BODY, :2])) < 10.0
            # the mirror image swaps left and right: its left shoulder is the mirrored right
            mirrored = 2 * w - 1 - s[SWAPPED, 0]
            assert np.median(np.abs(right[BODY, 0] - mirrored)) < 10.0
    # every region has been scanned once after ``scan`` frames
    assert np.mean(np.array(found[scan:]) == 2) >= 0.8, found


def test_bad_parameters_and_closing():
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(max_persons=0)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(detection_interval=0)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(threads=0)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(whole_frame_min_height=1.5)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector(whole_frame_min_height=0.3, whole_frame_leave_height=0.4)
    det = BlazePoseMultiDetector()
    det.close()
    det.close()
    with pytest.raises(RuntimeError):
        det.detect(np.zeros((64, 64, 3), np.uint8))


def test_change_outside_the_people_followed():
    rng = np.random.default_rng(0)
    ref = rng.integers(0, 256, (90, 160)).astype(np.uint8)
    ref = np.repeat(np.repeat(ref[::6, ::6], 6, axis=0), 6, axis=1)[:90, :160]  # blocky
    rr = picture_range(ref)
    assert not changed_outside(rr, ref.copy(), [])
    # the camera shaken by a pixel: every edge moves, nothing came in
    assert not changed_outside(rr, np.roll(ref, 1, axis=1), [(0, 0, 1, 90)])
    # somebody comes in: a patch changes
    now = ref.copy()
    now[40:52, 100:104] = 255 - now[40:52, 100:104]
    assert changed_outside(rr, now, [])
    # ... unless it is where a person followed is (or was)
    assert not changed_outside(rr, now, [(98, 38, 106, 54)])
    assert changed_outside(rr, now[:80], [])         # another image size: a change


def _wide(img, side):
    return np.concatenate([img, side], axis=1)


def test_searches_skipped_while_the_picture_is_still(clip_frames):
    """The committed clip, one person alone beside a grey side: once a whole round of
    regions at the longest interval found nobody, most searches are skipped (nothing else
    changes), one still made every ``still_detection_interval`` frames. Then a copy of the
    person steps into the grey side: searches are made again, and both are followed. (The
    finer squares for small people are left out: the counts below are those of the coarse
    regions' rounds.)"""
    frames = [f.image for f in clip_frames[:90]]
    frames = (frames + frames[-2::-1] + frames[1:]) * 2      # forwards, backwards, ...
    h, w = frames[0].shape[:2]
    grey = np.full((h, w // 2, 3), 127, np.uint8)
    counts = {}
    for still in (60, 0):
        with BlazePoseMultiDetector(max_persons=4, still_detection_interval=still,
                                    search_min_person_fraction=1.0) as det:
            for img in frames[:420]:
                det.detect(_wide(img, grey))
            counts[still] = (det.detections, det.searches_skipped)
            if not still:
                continue
            searches = det.detections
            for img in frames[:30]:                # the clip again: only the person moves
                det.detect(_wide(img, grey))
            assert det.detections - searches <= 1
            first = det.detections
            found = []
            for k, img in enumerate(frames[30:170]):
                other = img[:, ::-1][:, 200:200 + w // 2]   # the mirrored person comes in
                shift = max(0, w // 2 - 20 * k)
                side = grey.copy()
                side[:, shift:] = other[:, :w // 2 - shift]
                found.append(len(det.detect(_wide(img, side))))
            # searching again as things moved (at the longest interval, as without the
            # gate: each of the 5 regions every 75 frames), and the newcomer is found
            assert det.detections - first >= 6
            assert found[-30:].count(2) >= 27, found
    (gated, skipped), (plain, never) = counts[60], counts[0]
    assert never == 0 and skipped >= 10, counts
    assert gated <= plain - 8, counts


def test_fine_regions_cover_the_image_for_the_smallest_person():
    """Every person up to half the finest square high lies wholly in one finest square, the
    squares are sized for the smallest person asked for, and there are none where the coarse
    regions already show such a person large enough."""
    from mocap_keypoints.multipose import SMALL_PERSON_SIDE_FRACTION
    for w, h in ((360, 640), (640, 480), (1280, 720)):
        smallest = max(48.0, 0.1 * min(w, h))
        fine = BlazePoseMultiDetector.fine_regions(w, h, smallest)
        sides = sorted({x1 - x0 for x0, y0, x1, y1 in fine})
        assert sides[0] == round(smallest / SMALL_PERSON_SIDE_FRACTION), (w, h, sides)
        coarse = min(min(x1 - x0, y1 - y0) for x0, y0, x1, y1 in
                      BlazePoseMultiDetector.regions(w, h))
        assert max(sides) < coarse
        finest = [r for r in fine if r[2] - r[0] == sides[0]]
        assert all(0 <= x0 < x1 <= w and 0 <= y0 < y1 <= h for x0, y0, x1, y1 in finest)
        rng = np.random.default_rng(0)
        size = sides[0] // 2
        for x, y in zip(rng.integers(0, w - size, 300), rng.integers(0, h - size, 300)):
            assert any(x0 <= x and y0 <= y and x + size <= x1 and y + size <= y1
                       for x0, y0, x1, y1 in finest), (w, h, x, y)
    # a person a whole short side high needs no finer squares
    assert BlazePoseMultiDetector.fine_regions(640, 360, 360.0) == []


def test_the_search_cycle_takes_turns_between_coarse_regions_and_finer_squares():
    from mocap_keypoints.multipose import SMALLEST_SEARCHED_PX, interleave
    assert interleave(['a', 'b'], [1, 2, 3]) == ['a', 'b', 'a', 1, 'b', 2, 'a', 3]
    assert interleave(['a', 'b'], []) == ['a', 'b']
    coarse = BlazePoseMultiDetector.regions(640, 360)
    with BlazePoseMultiDetector(search_min_person_fraction=1.0) as det:
        assert det.search_regions(640, 360) == (coarse, len(coarse))
    # no lower bound in the settings: the squares stay sized for 32-px people
    with BlazePoseMultiDetector(min_person_px=0.0, search_min_person_fraction=0.0) as det:
        seq, per_round = det.search_regions(640, 360)
        assert per_round == 2 * len(coarse) and seq[:len(coarse)] == coarse
        sides = {x1 - x0 for x0, y0, x1, y1 in seq[len(coarse) + 1::2]}
        assert min(sides) == round(SMALLEST_SEARCHED_PX / 0.375)
    with pytest.raises(ValueError):
        BlazePoseMultiDetector.fine_regions(640, 360, 0.0)


def test_a_person_far_from_the_camera_is_found_by_the_finer_squares(clip_frames,
                                                                      clip_detections):
    """The committed clip shrunk to a person ~55 px high in a corner of a grey 640 x 360
    image: the regions of before never find them; the finer squares do, and the windows
    then follow them in most frames where the single-person detector sees the full-size
    person (keypoints within 10 % of their height)."""
    import cv2
    scale, x0, y0 = 0.19, 430, 210
    frames = [f.image for f in clip_frames]
    single = np.concatenate(clip_detections[0])
    order = list(range(len(frames))) + list(range(len(frames) - 1, -1, -1))
    order = (order * 2)[:180]

    def shrunk(img):
        canvas = np.full((360, 640, 3), 110, np.uint8)
        small = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        canvas[y0:y0 + small.shape[0], x0:x0 + small.shape[1]] = small
        return canvas

    results = {}
    for fraction in (0.1, 1.0):
        found, errors = [], []
        with BlazePoseMultiDetector(max_persons=4, search_min_person_fraction=fraction) as det:
            for k in order:
                got = det.detect(shrunk(frames[k]))
                found.append(len(got))
                ref = single[k]
                if len(got) == 1 and ref[BODY, 2].min() >= 0.5:
                    expect = ref[BODY, :2] * scale + [x0, y0]
                    errors.append(np.median(np.linalg.norm(got[0, BODY, :2] - expect, axis=1)))
            results[fraction] = (found, errors, det.fine_searches, det.found_in_fine)
    coarse, _, fine_searches, _ = results[1.0]
    assert max(coarse) == 0 and fine_searches == 0, coarse
    found, errors, fine_searches, found_in_fine = results[0.1]
    assert found_in_fine >= 1 and fine_searches >= found_in_fine
    first = next(i for i, n in enumerate(found) if n)
    assert first < 150 and max(found) == 1, found
    assert np.mean(np.array(found[first:]) == 1) >= 0.8, found
    assert np.median(errors) < 0.1 * 294 * scale, errors


def test_changed_patch_is_the_largest_moving_place():
    from mocap_keypoints.multipose import changed_patch
    diff = np.zeros((45, 160), bool)
    assert changed_patch(diff) is None
    diff[10:20, 100:104] = True                    # somebody walks in
    diff[30, 5] = diff[31, 7] = True               # a few scattered pixels elsewhere
    assert changed_patch(diff) == (100, 10, 104, 20)
    diff[12, 106] = True                           # a pixel of the same person, a gap away
    assert changed_patch(diff) == (100, 10, 107, 20)
    assert changed_patch(diff[:, :50]) is None     # fewer than 6 changed pixels
    diff[:, :60] = True                            # the camera moved: no one place
    assert changed_patch(diff) is None


def test_the_region_for_a_change_holds_it_and_shows_it_small_enough():
    from mocap_keypoints.multipose import GUIDED_GROWTH, SMALL_PERSON_SIDE_FRACTION
    with BlazePoseMultiDetector() as det:
        cycle = set(det.search_regions(640, 360)[0])
        rng = np.random.default_rng(1)
        for _ in range(200):
            side = float(rng.uniform(20, 120))
            x0, y0 = rng.uniform(0, 640 - side / 2), rng.uniform(0, 360 - side)
            box = (x0, y0, x0 + side / 2, y0 + side)
            r = det.region_for(640, 360, box)
            assert r in cycle
            assert r[0] <= box[0] and r[1] <= box[1] and box[2] <= r[2] and box[3] <= r[3]
            if r != (0, 0, 640, 360):
                assert min(r[2] - r[0], r[3] - r[1]) >= side / SMALL_PERSON_SIDE_FRACTION
        # a small moving patch gets one of the finest squares, the nearest around it
        r = det.region_for(640, 360, (300, 150, 310, 190))
        assert r[2] - r[0] == min(x1 - x0 for x0, y0, x1, y1 in cycle)
        assert r[0] <= 305 - 40 and 305 + 40 <= r[2]
        # a change as large as the picture: the whole image
        assert det.region_for(640, 360, (0, 0, 640, 300)) == (0, 0, 640, 360)
        # after looks that found nobody: a region for a person two and three times the
        # patch (only the edges of a moving person's clothes change), around it and
        # reaching further above and below it (the rest of the person)
        sides = []
        for growth in GUIDED_GROWTH:
            r = det.region_for(640, 360, (300, 150, 310, 190), growth)
            reach = 0.5 * (growth - 1) * 40
            assert r[0] <= 300 and 310 <= r[2]
            assert r[1] <= max(0, 150 - reach) and min(360, 190 + reach) <= r[3], (growth, r)
            sides.append(min(r[2] - r[0], r[3] - r[1]))
            if r != (0, 0, 640, 360):
                assert sides[-1] >= growth * 40 / SMALL_PERSON_SIDE_FRACTION
        assert sides == sorted(sides) and sides[0] < sides[1] < sides[2], sides


def test_somebody_walking_into_a_static_picture_is_looked_for_where_they_are(
        clip_frames, clip_detections):
    """The committed clip's person, followed, beside a grey side into which a small copy of
    the person (about 70 px high) walks from the right edge: the search looks where the
    picture changed and finds the newcomer soon after they are in; keeping to the cycle of
    regions finds them later."""
    import cv2
    frames = [f.image for f in clip_frames]
    single = np.concatenate(clip_detections[0])
    order = list(range(len(frames))) + list(range(len(frames) - 1, -1, -1))
    enter, n = 20, 110

    def small_person(k):
        kp = single[k]
        seen = kp[:, 2] >= 0.5
        (x0, y0), (x1, y1) = kp[seen, :2].min(0), kp[seen, :2].max(0)
        mx, my = 0.15 * (x1 - x0), 0.1 * (y1 - y0)
        crop = frames[k][int(max(0, y0 - my)):int(min(360, y1 + my)),
                         int(max(0, x0 - mx)):int(min(640, x1 + mx))]
        return cv2.resize(crop, None, fx=0.25, fy=0.25, interpolation=cv2.INTER_AREA)

    def scene(i, k):
        side = np.full((360, 640, 3), 110, np.uint8)
        if i >= enter:
            sp = small_person(k)
            x = 640 - 2 * (i - enter)           # 2 px per frame from the right edge
            w = min(sp.shape[1], 640 - x)
            side[200:200 + sp.shape[0], x:x + w] = sp[:, :w]
        return _wide(frames[k], side)

    first = {}
    for guided in (True, False):
        with BlazePoseMultiDetector(search_where_changed=guided) as det:
            found = []
            for i in range(n):
                got = det.detect(scene(i, order[i % len(order)]))
                found.append(bool(len(got)) and bool(np.any(got[:, BODY, 0].mean(1) > 640)))
                if i < enter:
                    assert len(got) == 1           # the clip's person alone, followed
            first[guided] = next((i for i, f in enumerate(found) if f), n)
            if guided:
                assert det.found_guided >= 1 and det.guided_searches >= det.found_guided
                assert all(found[first[guided]:]), found
            else:
                assert det.guided_searches == 0
    # in after about 25 frames (the copy is about 50 px wide), found within 15 more
    assert first[True] <= enter + 40, first
    assert first[False] >= first[True] + 20, first


def test_something_that_moves_and_is_nobody_takes_few_searches(clip_frames):
    """A square that changes its colour every frame beside the committed clip's person: the
    search looks there (nobody), a few times in a row, then keeps to its cycle for a round
    before it looks again; the person stays followed throughout."""
    from mocap_keypoints.multipose import GUIDED_MAX_MISSES
    frames = [f.image for f in clip_frames]
    order = list(range(len(frames))) + list(range(len(frames) - 1, -1, -1))
    rng = np.random.default_rng(0)
    with BlazePoseMultiDetector() as det:
        per_round = det.search_regions(1280, 360)[1]
        followed = []
        for i in range(450):
            side = np.full((360, 640, 3), 110, np.uint8)
            side[150:210, 300:360] = rng.integers(0, 256, 3, dtype=np.uint8)
            got = det.detect(_wide(frames[order[i % len(order)]], side))
            followed.append(int(np.sum(got[:, BODY, 0].mean(1) < 640)) if len(got) else 0)
        assert det.found_guided == 0
        assert det.guided_searches >= GUIDED_MAX_MISSES
        # (every other search would look there without the pause: about half of them)
        cycles = 1 + det.detections // (per_round + 2 * GUIDED_MAX_MISSES)
        assert det.guided_searches <= GUIDED_MAX_MISSES * cycles, \
            (det.guided_searches, det.detections, per_round)
        assert np.mean(np.array(followed[5:]) == 1) >= 0.95


def test_looks_where_the_picture_changed_are_not_searches_of_the_round():
    """The interval doubles after a whole round of the coarse regions found nobody new; the
    looks where the picture changed that come between them (every other search at most) do
    not count as the round's searches, so a round still covers every coarse region."""
    with BlazePoseMultiDetector() as det:
        regions = det.search_regions(640, 360)[1]
        start = det._interval
        for _ in range(regions - 1):
            det._back_off(0, regions)
            det._back_off(0, regions, guided=True)
        assert det._interval == start              # one region of the round still to come
        det._back_off(0, regions, guided=True)
        assert det._interval == start
        det._back_off(0, regions)
        assert det._interval == min(2 * start, det.max_detection_interval)
        det._back_off(1, regions, guided=True)     # someone new, however found
        assert det._interval == det.detection_interval


def test_the_looks_start_afresh_when_nobody_is_followed(clip_frames):
    """The sizes, misses and pause of the looks where the picture changed were about the
    scene before: when the last window ends they start afresh."""
    frames = [f.image for f in clip_frames]
    with BlazePoseMultiDetector() as det:
        for image in frames[:10]:
            det.detect(image)
        assert len(det._windows) == 1
        det._growth, det._misses, det._guided_pause = 2, 3, 5
        grey = np.full_like(frames[0], 110)
        for _ in range(det.max_missed + 2):
            det.detect(grey)
        assert not det._windows
        assert (det._growth, det._misses, det._guided_pause) == (0, 0, 0)
