import numpy as np
import pytest

from mocap_core.camera import (CameraCalibration, CameraIntrinsics, read_camera_info_yaml,
                               scale_intrinsics, write_camera_info_yaml)

# As written by ROS camera_calibration (camera_calibration_parsers), monocular.
STANDARD_YAML = """\
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [612.3, 0, 318.7, 0, 611.9, 242.1, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [0.11, -0.23, 0.001, -0.002, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [620.1, 0, 318.2, 0, 0, 619.5, 241.7, 0, 0, 0, 1, 0]
"""


def test_read_standard_camera_info_yaml(tmp_path):
    path = tmp_path / 'cam.yaml'
    path.write_text(STANDARD_YAML)
    cal = read_camera_info_yaml(path)
    i = cal.intrinsics
    assert (i.width, i.height, i.fx, i.fy, i.cx, i.cy) == (640, 480, 612.3, 611.9, 318.7, 242.1)
    assert cal.distortion_model == 'plumb_bob' and cal.camera_name == 'narrow_stereo'
    assert cal.distortion == (0.11, -0.23, 0.001, -0.002, 0.0) and cal.has_distortion
    assert not i.approximate


def test_camera_info_yaml_roundtrip(tmp_path):
    cal = CameraCalibration(CameraIntrinsics(1280, 720, 1000.5, 1001.5, 640.25, 360.75),
                            'rational_polynomial', tuple(np.linspace(-0.1, 0.1, 8)), 'webcam')
    write_camera_info_yaml(cal, tmp_path / 'c.yaml')
    assert read_camera_info_yaml(tmp_path / 'c.yaml') == cal
    plain = CameraCalibration(CameraIntrinsics(64, 48, 50.0, 50.0, 31.5, 23.5))
    write_camera_info_yaml(plain, tmp_path / 'p.yaml')
    back = read_camera_info_yaml(tmp_path / 'p.yaml')
    assert back.intrinsics == plain.intrinsics and not back.has_distortion


@pytest.mark.parametrize('text, reason', [
    ('image_width: [unclosed', 'cannot read calibration YAML'),
    ('- just\n- a list\n', 'not a camera_info YAML'),
    ('image_width: 640\nimage_height: 480\n', 'camera_matrix'),
    (STANDARD_YAML.replace('image_height: 480\n', ''), "missing 'image_height'"),
    (STANDARD_YAML.replace('612.3, 0, 318.7, ', ''), 'has 6 values, expected 9'),
    (STANDARD_YAML.replace('612.3', '-5'), 'invalid calibration'),
    (STANDARD_YAML.replace('image_width: 640', 'image_width: wide'), 'invalid calibration'),
])
def test_bad_calibration_files_raise_naming_the_file(tmp_path, text, reason):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ValueError, match=reason) as info:
        read_camera_info_yaml(path)
    assert 'bad.yaml' in str(info.value)


def test_missing_calibration_file(tmp_path):
    with pytest.raises(FileNotFoundError, match='calibration file not found'):
        read_camera_info_yaml(tmp_path / 'none.yaml')


def test_scale_intrinsics_keeps_the_field_of_view():
    intr = CameraIntrinsics.from_fov(1280, 720, 70.0)
    half = scale_intrinsics(intr, 640, 360)
    assert half.approximate and half.fx == pytest.approx(intr.fx / 2)
    assert (half.cx, half.cy) == pytest.approx(((640 - 1) / 2, (360 - 1) / 2))
    # A point keeps its viewing ray: same normalised coordinates.
    p = np.array([0.3, -0.2, 2.0])
    np.testing.assert_allclose((half.project(p) + 0.5) * 2 - 0.5, intr.project(p))
