import json
import os
import shutil

import cv2
import numpy as np
import pytest

from mocap_core.data.openpose import list_openpose_files, read_openpose_file
from mocap_keypoints.sources import (CameraSource, Frame, ImageDirectorySource, OpenPoseSource,
                                     SourceError, VideoSource, check_image, open_source,
                                     parse_device, resolve_kind)
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
CLIP = ROOT / 'data' / 'video_example' / 'taiji_640x360.mp4'
CLIP_INFO = json.loads(CLIP.with_suffix('.json').read_text())
OPENPOSE = ROOT / 'data' / 'openpose_example' / 'seq1'


def test_video_frames_and_stamps(clip_frames):
    fps = CLIP_INFO['fps']
    assert [f.index for f in clip_frames] == list(range(96))
    for f in clip_frames:
        stamp, image = f  # a frame unpacks as (stamp_ns, BGR image)
        assert image.shape == (360, 640, 3) and image.dtype == np.uint8
        assert stamp == round(f.index * 1e9 / fps)
        assert f.error is None
    assert np.diff([f.stamp_ns for f in clip_frames]) == pytest.approx(1e9 / fps, abs=1e3)


def test_video_start_time_fps_override_and_loop():
    with VideoSource(CLIP, fps=10.0, loop=True, clock_ns=lambda: 5_000_000_000) as src:
        assert src.fps == 10.0 and src.file_fps == pytest.approx(23.976, abs=1e-3)
        frames = []
        for f in src:
            frames.append(f)
            if len(frames) == 100:
                break
    stamps = [f.stamp_ns for f in frames]
    assert stamps[0] == 5_000_000_000 and stamps[99] == 5_000_000_000 + 9_900_000_000
    assert np.all(np.diff(stamps) > 0)                     # stamps go on across the loop
    np.testing.assert_array_equal(frames[96].image, frames[0].image)  # back at the start
    assert frames[96].name == 'frame 0' and frames[96].index == 96


def test_video_end_is_reported():
    with VideoSource(CLIP) as src:
        n = sum(1 for _ in src)
    assert n == 96 and src.ended_reason == 'video ended after 96 frames'


def _small_avi(path, n=20):
    cap = cv2.VideoCapture(str(CLIP))
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 24, (160, 90))
    for _ in range(n):
        writer.write(cv2.resize(cap.read()[1], (160, 90)))
    writer.release()
    return path.read_bytes()


def test_corrupt_frame_in_a_video_is_skipped_with_a_message(tmp_path):
    data = bytearray(_small_avi(tmp_path / 'ok.avi'))
    starts = [i for i in range(len(data) - 1) if data[i] == 0xFF and data[i + 1] == 0xD8]
    data[starts[10]:starts[10] + 400] = bytes(range(256)) + bytes(144)  # break frame 10
    bad = tmp_path / 'bad.avi'
    bad.write_bytes(bytes(data))
    with VideoSource(bad) as src:
        frames = list(src)
    errors = [f for f in frames if f.error]
    assert len(frames) == 20 and [f.index for f in errors] == [10]
    assert 'bad.avi' in errors[0].error and 'cannot decode frame 10' in errors[0].error
    assert errors[0].image is None


def test_truncated_videos(tmp_path):
    data = _small_avi(tmp_path / 'ok.avi')
    cut = tmp_path / 'cut.avi'
    cut.write_bytes(data[:len(data) // 2])
    with VideoSource(cut) as src:
        frames = list(src)  # ends without raising
    good = [f for f in frames if f.error is None]
    assert 5 <= len(good) < 20 and 'video ended' in src.ended_reason
    mp4 = tmp_path / 'cut.mp4'
    mp4.write_bytes(CLIP.read_bytes()[:200_000])  # MP4 index at the end: unreadable
    with pytest.raises(SourceError, match='cannot open video file'):
        VideoSource(mp4)


@pytest.mark.parametrize('content, reason', [
    (None, 'not found'),
    (b'', 'cannot open video file'),
    (b'this is a text file, not a video\n' * 50, 'cannot open video file'),
])
def test_unreadable_video_files_raise(tmp_path, content, reason):
    path = tmp_path / 'clip.mp4'
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(SourceError, match=reason):
        VideoSource(path)


def test_image_directory_order_stamps_and_bad_files(tmp_path, clip_frames):
    d = tmp_path / 'imgs'
    d.mkdir()
    for k in (1, 2, 10):
        cv2.imwrite(str(d / f'img{k}.png'), clip_frames[k].image)
    cv2.imwrite(str(d / 'img3.jpg'), cv2.resize(clip_frames[3].image, (320, 180)))
    (d / 'img4.jpg').write_bytes(b'\xff\xd8\xff\xe0' + bytes(500))   # corrupt JPEG
    (d / 'img5.png').write_bytes(b'')                                # empty file
    cv2.imwrite(str(d / 'img6.png'), np.zeros((4, 4, 3), np.uint8))  # too small
    (d / 'notes.txt').write_text('not an image')                     # ignored
    with ImageDirectorySource(d, fps=20, clock_ns=lambda: 1_000) as src:
        frames = list(src)
    assert [f.name for f in frames] == ['img1.png', 'img2.png', 'img3.jpg', 'img4.jpg',
                                        'img5.png', 'img6.png', 'img10.png']
    assert [f.stamp_ns for f in frames] == [1_000 + k * 50_000_000 for k in range(7)]
    np.testing.assert_array_equal(frames[0].image, clip_frames[1].image)
    assert frames[2].image.shape == (180, 320, 3)
    errors = {f.name: f.error for f in frames if f.error}
    assert set(errors) == {'img4.jpg', 'img5.png', 'img6.png'}
    assert 'img4.jpg' in errors['img4.jpg'] and 'not a readable image' in errors['img4.jpg']
    assert 'empty file' in errors['img5.png'] and 'too small' in errors['img6.png']
    assert src.frames_bad == 3 and src.frames_read == 4


def test_image_directory_errors(tmp_path):
    with pytest.raises(SourceError, match='not found'):
        ImageDirectorySource(tmp_path / 'nope')
    (tmp_path / 'a.txt').write_text('x')
    with pytest.raises(SourceError, match='no image files'):
        ImageDirectorySource(tmp_path)


def test_openpose_source_reproduces_the_json_and_names_bad_files(tmp_path):
    with OpenPoseSource(OPENPOSE, fps=30, clock_ns=lambda: 0) as src:
        frames = list(src)
    files = list_openpose_files(OPENPOSE)
    assert len(frames) == len(files) == 81
    for f, (_, path) in zip(frames, files):
        np.testing.assert_array_equal(f.keypoints, read_openpose_file(path))
        assert f.name == path.name
    d = tmp_path / 'op'
    shutil.copytree(OPENPOSE, d)
    bad = sorted(d.glob('*.json'))[2]
    bad.write_text('{"people": [{"pose_keypoints_2d": [1, 2')
    frames = list(OpenPoseSource(d))
    errs = [f for f in frames if f.error]
    assert len(errs) == 1 and bad.name in errs[0].error and errs[0].keypoints is None
    with pytest.raises(SourceError, match='not found'):
        OpenPoseSource(tmp_path / 'missing')


def test_missing_cameras_raise_clear_errors():
    with pytest.raises(SourceError, match='camera device not found: /dev/video_nope'):
        CameraSource('/dev/video_nope')
    with pytest.raises(SourceError, match="camera not found or cannot be opened: device '57'"):
        CameraSource('57')
    assert parse_device('3') == 3 and parse_device('/dev/video1') == '/dev/video1'


def test_resolve_kind_and_open_source(tmp_path):
    assert resolve_kind('auto', '') == 'camera'
    assert resolve_kind('auto', str(CLIP)) == 'video'
    assert resolve_kind('auto', str(OPENPOSE)) == 'openpose_json'
    assert resolve_kind('auto', str(tmp_path)) == 'images'
    assert resolve_kind('topic', '') == 'topic'
    with pytest.raises(ValueError, match='unknown source'):
        resolve_kind('webcam', '')
    with pytest.raises(SourceError, match='path not found'):
        resolve_kind('auto', str(tmp_path / 'x.mp4'))
    with pytest.raises(SourceError, match='needs the path parameter'):
        open_source('video', '')
    src = open_source('video', str(CLIP))
    assert src.kind == 'video' and '96 frames' in src.description
    src.close()


def test_check_image_normalises_and_rejects():
    gray = np.full((20, 30), 7, np.uint8)
    assert check_image(gray).shape == (20, 30, 3)
    bgra = np.zeros((20, 30, 4), np.uint8)
    bgra[..., 0] = 9
    out = check_image(bgra)
    assert out.shape == (20, 30, 3) and out[0, 0, 0] == 9 and out.flags['C_CONTIGUOUS']
    with pytest.raises(ValueError, match='x.png: empty frame'):
        check_image(None, 'x.png')
    frame = Frame(5, out)
    stamp, img = frame
    assert stamp == 5 and img is out


def test_unreadable_image_file(tmp_path):
    if os.geteuid() == 0:
        pytest.skip('root reads files without permission bits')
    d = tmp_path / 'imgs'
    d.mkdir()
    p = d / 'a.png'
    cv2.imwrite(str(p), np.zeros((32, 32, 3), np.uint8))
    p.chmod(0)
    frames = list(ImageDirectorySource(d))
    assert 'cannot read file' in frames[0].error


def test_video_json_description():
    info = json.loads(CLIP.with_suffix('.json').read_text())
    assert info['frames'] == 96 and CLIP.stat().st_size < 1_000_000


def test_camera_source_reads_a_stream_and_gives_up_when_it_stops():
    """OpenCV opens a video file like a stream URL: the camera code path without a camera."""
    ticks = iter(range(10**9, 2 * 10**9, 1000))
    src = CameraSource(str(CLIP), max_failures=3, clock_ns=lambda: next(ticks))
    assert src.live and 'camera' in src.description
    frames = []
    with pytest.raises(SourceError, match='delivered no frame in 3 tries'):
        for f in src:
            frames.append(f)
    src.close()
    good = [f for f in frames if f.error is None]
    assert len(good) == 96 and good[0].image.shape == (360, 640, 3)
    assert np.all(np.diff([f.stamp_ns for f in frames]) > 0)  # the clock at each grab
    assert [f.error is not None for f in frames[96:]] == [True, True]
    assert 'failed to grab frame 96' in frames[96].error
