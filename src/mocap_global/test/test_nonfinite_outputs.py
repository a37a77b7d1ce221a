"""A non-finite network output must not poison the accumulated world pose: the frame holds the
last finite motion, is counted, and every later frame comes out finite with the network's own
motion (streaming level, :class:`OnlineGMR`, and node level, :class:`GMRNode` in-process)."""

from __future__ import annotations

from typing import Dict, List, Optional, Sequence

import numpy as np
import pytest
import torch
from torch import nn

from mocap_core.pose import Pose
from mocap_core.testing import random_walk_poses
from mocap_core.rotations import quat_to_matrix

from mocap_global.model import GMR, GMRConfig
from mocap_global.online import OnlineGMR, StaticCameraFusion, WorldFrame

DT_NS = 33_333_333


class NaNOnCalls(nn.Module):
    """A model whose outputs are all NaN on the given (1-based) forward calls."""

    def __init__(self, model: nn.Module, bad_calls: Sequence[int]) -> None:
        super().__init__()
        self.model = model
        self.cfg = model.cfg
        self.bad_calls = set(bad_calls)
        self.calls = 0

    def forward(self, x: torch.Tensor,
                lengths: Optional[torch.Tensor] = None) -> Dict[str, torch.Tensor]:
        out = self.model(x, lengths)
        self.calls += 1
        if self.calls in self.bad_calls:
            out = {k: torch.full_like(v, float('nan')) for k, v in out.items()}
        return out


def _model() -> GMR:
    """A small network whose motions are clearly not zero: about 0.03 rad about z and 4 cm
    forward per frame."""
    torch.manual_seed(0)
    model = GMR(GMRConfig(layers=1, hidden=16, projection=16, window=24))
    c = model.cfg.num_features
    model.set_normalisation(np.zeros(c), np.ones(c), [0.0, 0.0, 0.03, 0.04, 0.0, 0.0],
                            [0.01, 0.01, 0.01, 0.01, 0.01, 0.01])
    return model.eval()


def _poses(n: int, seed: int = 0) -> List[Pose]:
    return random_walk_poses(n, seed, start=(0.0, 0.0, 3.0), step=(0.05, 0.0, 0.0))


class NaNEngineOnCalls:
    """The NumPy engine (:class:`~mocap_global.inference.NumpyGMR`) with all outputs NaN on
    the given (1-based) calls."""

    def __init__(self, engine, bad_calls: Sequence[int]) -> None:
        self.engine = engine
        self.bad_calls = set(bad_calls)
        self.calls = 0

    def __call__(self, x: np.ndarray) -> Dict[str, np.ndarray]:
        out = self.engine(x)
        self.calls += 1
        if self.calls in self.bad_calls:
            out = {k: np.full_like(v, np.nan) for k, v in out.items()}
        return out


def _run(model: nn.Module, poses: Sequence[Pose], nan_engine_calls: Sequence[int] = (),
         **kwargs) -> tuple:
    online = OnlineGMR(model, **kwargs)
    if nan_engine_calls:
        assert online.inference == 'numpy'
        online._numpy = NaNEngineOnCalls(online._numpy, nan_engine_calls)
    frames: List[WorldFrame] = []
    for i, p in enumerate(poses):
        frames += online.push(i * DT_NS, p)[0]
    frames += online.flush()
    return online, frames


def _relative_motions(frames: Sequence[WorldFrame]) -> tuple:
    """Body-frame motions between consecutive output frames: (N-1, 3, 3), (N-1, 3)."""
    R = quat_to_matrix(np.stack([f.pose.rotations[0] for f in frames]))
    T = np.stack([f.pose.root_position for f in frames])
    Rt = np.swapaxes(R[:-1], -1, -2)
    return Rt @ R[1:], (Rt @ (T[1:] - T[:-1])[..., None])[..., 0]


def _all_finite(frames: Sequence[WorldFrame]) -> bool:
    return all(np.all(np.isfinite(f.pose.rotations)) and np.all(np.isfinite(f.pose.root_position))
               and np.all(np.isfinite(f.linear_velocity))
               and np.all(np.isfinite(f.angular_velocity)) for f in frames)


@pytest.mark.parametrize('chunk', [1, 4])
@pytest.mark.parametrize('engine', ['torch', 'numpy'])
def test_one_nan_window_holds_the_last_motion_and_the_stream_carries_on(chunk, engine):
    poses = _poses(40)
    kwargs = dict(lookahead=3, window=16, chunk=chunk, inference=engine)
    _, ref = _run(_model(), poses, **kwargs)
    bad_call = 6                      # the sixth network pass: frames 5 * chunk onwards
    if engine == 'numpy':
        online, frames = _run(_model(), poses, nan_engine_calls=[bad_call], **kwargs)
    else:
        online, frames = _run(NaNOnCalls(_model(), [bad_call]), poses, **kwargs)
    assert [f.stamp_ns for f in frames] == [f.stamp_ns for f in ref]
    assert _all_finite(frames)
    held = [i for i, f in enumerate(frames) if f.held]
    first = (bad_call - 1) * chunk
    assert held == list(range(first, first + chunk))
    assert online.nonfinite_outputs == chunk
    dR, dT = _relative_motions(frames)
    dR_ref, dT_ref = _relative_motions(ref)
    # a held frame repeats the last finite motion (constant velocity) ...
    for i in held:
        np.testing.assert_allclose(dR[i - 1], dR_ref[first - 2], atol=1e-6)
        np.testing.assert_allclose(dT[i - 1], dT_ref[first - 2], atol=1e-6)
    # ... and every other frame, before and after, moves by the network's own motion
    others = [j for j in range(len(dR)) if j + 1 not in held]
    np.testing.assert_allclose(dR[others], dR_ref[others], atol=1e-6)
    np.testing.assert_allclose(dT[others], dT_ref[others], atol=1e-6)
    assert not np.allclose(dT_ref[first - 1], dT_ref[first - 2], atol=1e-4)  # a real change


def test_nan_in_the_first_window_starts_level_and_the_fusion_stays_clean():
    """The first pose's tilt comes from the up estimate: a NaN one gives a level first pose;
    a static-camera fusion estimating its frame sees only finite poses."""
    poses = _poses(40)
    fusion = StaticCameraFusion(30.0, init_s=0.5)
    online, frames = _run(NaNOnCalls(_model(), [1, 3]), poses, lookahead=3, window=16,
                          fusion=fusion)
    assert len(frames) == 40 and _all_finite(frames)
    assert frames[0].held and frames[2].held and online.nonfinite_outputs == 2
    np.testing.assert_allclose(quat_to_matrix(frames[0].pose.rotations[0])[2], [0, 0, 1],
                               atol=1e-9)
    assert fusion.ready and np.all(np.isfinite(fusion.W_R)) and np.all(np.isfinite(fusion.W_t))
    assert frames[-1].fused


def test_gmr_node_publishes_finite_frames_after_a_nan_output():
    """In-process GMRNode (as ``mocap process`` wires it): one NaN network pass, then every
    later frame is still published, finite, and the count is on the diagnostics."""
    import rclpy
    from rclpy.parameter import Parameter

    from mocap_core import ros_conversions as rc
    from mocap_core import topics
    from mocap_core.inprocess import InProcessGraph

    from mocap_global.node import GMRNode

    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    try:
        out = []
        graph = InProcessGraph(record=lambda t, m, q: out.append((t, m)))
        node = graph.add(GMRNode(context=context, parameter_overrides=[
            Parameter('motion_topic', value='/in/motion'), Parameter('lookahead', value=5)]))
        node.model = NaNOnCalls(node.model, [4])
        poses = _poses(30)
        for i, p in enumerate(poses):
            graph.publish('/in/motion', rc.pose_to_motion(p, rc.make_header(i * DT_NS, 'floor')))
        graph.flush()
        world = [rc.motion_to_pose(m) for t, m in out if t == topics.WORLD_MOTION]
        assert len(world) == len(poses)
        assert all(np.all(np.isfinite(p.joint_positions())) for p in world)
        odom = [rc.odometry_to_root(m)[0] for t, m in out if t == topics.WORLD_ODOM]
        assert len(odom) == len(poses) and np.all(np.isfinite(odom))
        floors = [m for t, m in out if t == topics.WORLD_FLOOR]
        assert len(floors) == len(poses)
        assert all(m.header.frame_id == 'world' and m.child_frame_id == 'floor'
                   and m.transform.translation.z == 0.0 for m in floors)
        values = {kv.key: kv.value for kv in node.diag.status().values}
        assert values['nonfinite_outputs'] == '1'
        assert values['errors'] == '0' and values['frames_dropped'] == '0'
        node.destroy_node()
    finally:
        context.try_shutdown()
