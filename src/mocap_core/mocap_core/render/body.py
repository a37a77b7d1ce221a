"""An Anny body driven by a pipeline motion, and its exact 18-joint ground truth (no ROS).

The body is ``anny.Anny(rig="cmu_mb")``: the MakeHuman mesh (13,718 vertices) skinned to a
31-bone rig whose bones carry the CMU MotionBuilder BVH names. Two choices make rendered and
projected training samples teach the *same* skeleton:

* **Which points are the joints.** The pipeline joints are read off the posed rig with the
  mapping the retargeting uses for CMU MotionBuilder BVH files (``data/retarget.py``,
  ``_MB2_LEFT``): hip = ``LeftUpLeg`` head, knee = ``LeftLeg``, ankle = ``LeftFoot``, toe =
  ``LeftToeBase``, spine = ``Spine``, head = ``Head``, shoulder = ``LeftArm``, elbow =
  ``LeftForeArm``, wrist = ``LeftHand``; pelvis = mean of the hips, neck = mean of the
  shoulders. These points are exact: they are where the rendered mesh's joints are.
* **How the motion drives the bones.** Each rig bone takes the *global* rotation of one
  pipeline joint (the joint whose rotation orients that segment in the pipeline skeleton:
  the thigh takes ``left_hip``'s, the shin ``left_knee``'s, ...), composed with a fixed rest
  correction that turns Anny's A-pose segment onto the pipeline's T-pose direction (the
  smallest rotation between the two directions; identity for the trunk, whose rest is
  upright in both). So every limb segment of the rendered body points exactly where the
  motion's segment points; only the trunk keeps Anny's own curvature.

Frames. Anny's rest frame is z up, facing -y, left +x; the pipeline's body frame is x
forward, y left, z up. Everything here is in the pipeline's convention (world z up, floor at
z = 0, metres); :data:`ANNY_TO_PIPELINE` converts. Rotation matrices act on column vectors.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from ..rotations import quat_to_matrix
from ..skeleton import (BONE_GROUPS, JOINT_INDEX, JOINT_NAMES, NUM_JOINTS, PARENTS,
                        REST_DIRECTIONS, Skeleton)

#: Anny rest coordinates -> pipeline body coordinates: (x, y, z) -> (-y, x, z).
ANNY_TO_PIPELINE = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])

#: Rig bone -> (pipeline joint whose global rotation drives it, segment target).
#: The target is the pipeline joint whose rest direction the bone's rest direction is turned
#: onto (None: no correction, the bone keeps Anny's rest orientation relative to the driver;
#: ``'=<bone>'``: the same correction as that bone, so the two stay rigid as in Anny's rest).
_LEFT_DRIVERS: Dict[str, Tuple[str, Optional[str]]] = {
    'LHipJoint': ('pelvis', None),
    'LeftUpLeg': ('left_hip', 'left_knee'),
    'LeftLeg': ('left_knee', 'left_ankle'),
    'LeftFoot': ('left_ankle', 'left_toe'),
    'LeftToeBase': ('left_toe', '=LeftFoot'),
    'LeftShoulder': ('neck', None),
    'LeftArm': ('left_shoulder', 'left_elbow'),
    'LeftForeArm': ('left_elbow', 'left_wrist'),
    'LeftHand': ('left_wrist', '=LeftForeArm'),
    'LThumb': ('left_wrist', '=LeftForeArm'),
    'LeftFingerBase': ('left_wrist', '=LeftForeArm'),
    'LeftHandFinger1': ('left_wrist', '=LeftForeArm'),
}


def _right(name: str) -> str:
    if name.startswith('Left'):
        return 'Right' + name[4:]
    if name.startswith('L'):
        return 'R' + name[1:]
    return name


def _right_joint(name: Optional[str]) -> Optional[str]:
    if name is None or name.startswith('='):
        return None if name is None else '=' + _right(name[1:])
    return name.replace('left_', 'right_')


BONE_DRIVERS: Dict[str, Tuple[str, Optional[str]]] = {
    'Hips': ('pelvis', None),
    'LowerBack': ('pelvis', None),
    'Spine': ('spine', None),
    'Spine1': ('spine', None),
    'Neck': ('neck', None),
    'Neck1': ('neck', None),
    'Head': ('head', None),
    **_LEFT_DRIVERS,
    **{_right(b): (_right_joint(j), _right_joint(t)) for b, (j, t) in _LEFT_DRIVERS.items()},
}

#: Pipeline joint -> rig bones whose posed heads average to it (as for CMU mb2 BVH files).
JOINT_POINTS: Dict[str, Tuple[str, ...]] = {
    'pelvis': ('LeftUpLeg', 'RightUpLeg'),
    'left_hip': ('LeftUpLeg',), 'left_knee': ('LeftLeg',), 'left_ankle': ('LeftFoot',),
    'left_toe': ('LeftToeBase',),
    'right_hip': ('RightUpLeg',), 'right_knee': ('RightLeg',), 'right_ankle': ('RightFoot',),
    'right_toe': ('RightToeBase',),
    'spine': ('Spine',), 'neck': ('LeftArm', 'RightArm'), 'head': ('Head',),
    'left_shoulder': ('LeftArm',), 'left_elbow': ('LeftForeArm',), 'left_wrist': ('LeftHand',),
    'right_shoulder': ('RightArm',), 'right_elbow': ('RightForeArm',),
    'right_wrist': ('RightHand',),
}

#: Where the pipeline's convention puts the joints whose placement differs between skeleton
#: sources: the hip joints' distance from the pelvis centre over the thigh length, the
#: shoulders' distance from the neck over the upper arm, the head joint's height above the
#: neck over the neck bone. Medians over the skeletons of the 2,529 training clips
#: (``mocap data build``, 2026-11-23; 98 % Bandai Namco): 0.166, 0.412, 0.463. Anny's rig
#: puts these points where CMU's rig does (0.26, 0.65, 0.85 for the default body), so the
#: rendered ground truth moves them onto the training convention: the hips and shoulders
#: towards the body's midline and the head joint down towards the neck, along the rig's own
#: segments. The rig's own points are kept as ``joints_rig``.
CONVENTION_RATIOS: Dict[str, float] = {'hip_over_thigh': 0.166,
                                       'clavicle_over_upper_arm': 0.412,
                                       'head_over_neck': 0.463}

#: Body regions for clothing colours: rig bone -> region.
BONE_REGIONS: Dict[str, str] = {
    **{b: 'trunk' for b in ('Hips', 'LowerBack', 'Spine', 'Spine1', 'LeftShoulder',
                            'RightShoulder')},
    **{b: 'neck' for b in ('Neck', 'Neck1')},
    'Head': 'head',
    **{b: 'upper_arm' for b in ('LeftArm', 'RightArm')},
    **{b: 'forearm' for b in ('LeftForeArm', 'RightForeArm')},
    **{b: 'hand' for b in ('LeftHand', 'RightHand', 'LThumb', 'RThumb', 'LeftFingerBase',
                           'RightFingerBase', 'LeftHandFinger1', 'RightHandFinger1')},
    **{b: 'hips' for b in ('LHipJoint', 'RHipJoint')},
    **{b: 'thigh' for b in ('LeftUpLeg', 'RightUpLeg')},
    **{b: 'shin' for b in ('LeftLeg', 'RightLeg')},
    **{b: 'foot' for b in ('LeftFoot', 'RightFoot', 'LeftToeBase', 'RightToeBase')},
}

#: Phenotype ranges sampled for rendered people (Anny's parameters in [0, 1]; age 0.5 is a
#: child, 0.75 a young adult, 1.0 old; below 0.6 the motion-capture adults' motion would be
#: played by small children, so the range starts there). Anny's ``height`` parameter spans
#: 1.2-2.4 m; it is not drawn but solved for a standing height drawn from
#: :data:`ADULT_HEIGHT_M` (see :func:`sample_phenotype`).
PHENOTYPE_RANGES: Dict[str, Tuple[float, float]] = {
    'gender': (0.0, 1.0), 'age': (0.6, 1.0), 'muscle': (0.1, 0.9), 'weight': (0.1, 0.95),
    'proportions': (0.2, 0.8),
}
#: Adult standing height (m): mean for gender 0 (Anny's male) and 1 (female), standard
#: deviation, and the clip range (roughly the 1st-99th percentiles of adult populations).
ADULT_HEIGHT_M = {'male_mean': 1.76, 'female_mean': 1.63, 'sd': 0.075, 'range': (1.48, 1.98)}


def default_cache_dir() -> Path:
    """Where Anny's built model files are kept (``ANNY_CACHE_DIR``, else
    ``~/.cache/mocap/anny``; about 880 MB after the first build, which takes ~60 s)."""
    return Path(os.environ.get('ANNY_CACHE_DIR')
                or Path.home() / '.cache' / 'mocap' / 'anny')


def load_anny():
    """The Anny model with the CMU MotionBuilder rig, dense (torch) skinning and world-orient
    pose parameters. Raises :class:`~mocap_core.render.RendererUnavailable` without ``anny``."""
    from . import RendererUnavailable
    os.environ.setdefault('ANNY_CACHE_DIR', str(default_cache_dir()))
    try:
        import anny
    except ImportError as exc:
        raise RendererUnavailable(
            f'the anny body model is not installed ({exc}); run scripts/setup.sh, which '
            'installs requirements/render.txt') from None
    return anny.Anny(rig='cmu_mb', skinning_method='lbs', pose_parameterization='world-orient')


def sample_phenotype(rng: np.random.Generator, model=None) -> Dict[str, float]:
    """A random adult body: :data:`PHENOTYPE_RANGES` drawn uniformly, and, given the Anny
    ``model``, the ``height`` parameter that gives a standing height drawn from
    :data:`ADULT_HEIGHT_M` for the drawn gender (bisection on the rest mesh, +-5 mm)."""
    p = {k: float(rng.uniform(*r)) for k, r in PHENOTYPE_RANGES.items()}
    h = ADULT_HEIGHT_M
    mean = h['male_mean'] + (h['female_mean'] - h['male_mean']) * p['gender']
    target = float(np.clip(rng.normal(mean, h['sd']), *h['range']))
    p['target_height_m'] = target
    if model is None:
        p['height'] = 0.5
        return p
    lo, hi = 0.0, 1.0
    for _ in range(12):
        mid = 0.5 * (lo + hi)
        got = AnnyBody.create(model, {**_anny_params(p), 'height': mid}).height()
        if abs(got - target) < 0.005:
            break
        lo, hi = (mid, hi) if got < target else (lo, mid)
    p['height'] = mid
    return p


def _anny_params(p: Mapping[str, float]) -> Dict[str, float]:
    """The Anny phenotype parameters of a sampled body (drops bookkeeping keys)."""
    return {k: float(v) for k, v in p.items() if k in PHENOTYPE_RANGES or k == 'height'}


def _min_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) smallest rotation taking direction ``a`` onto ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    if np.linalg.norm(v) < 1e-12:
        if c > 0:
            return np.eye(3)
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + c)


@dataclass
class PosedBody:
    """One posed clip of a body (pipeline world frame, z up, metres).

    Attributes:
        vertices: (F, V, 3) float32 mesh vertices.
        joints: (F, 18, 3) the pipeline joints of this body in the training convention
            (:func:`to_convention`).
        joints_rig: (F, 18, 3) the same at the rig's points (:data:`JOINT_POINTS`).
        bone_heads: (F, B, 3) every rig bone's head.
    """

    vertices: np.ndarray
    joints: np.ndarray
    joints_rig: np.ndarray
    bone_heads: np.ndarray


@dataclass
class AnnyBody:
    """One person: an Anny phenotype, its rest rig in pipeline axes, and the rest corrections.

    Build with :meth:`create`. ``rest_heads`` (B, 3) and ``rest_rotations`` (B, 3, 3) are the
    rest bones in pipeline axes; ``corrections`` (B, 3, 3) the rest corrections (module
    docstring); ``faces`` (T, 3) the triangles; ``vertex_bones`` (V,) each vertex's most
    weighted bone.
    """

    phenotype: Dict[str, float]
    bone_names: List[str]
    parents: np.ndarray
    rest_heads: np.ndarray
    rest_rotations: np.ndarray
    corrections: np.ndarray
    drivers: np.ndarray
    faces: np.ndarray
    vertex_bones: np.ndarray
    rest_tips: np.ndarray
    aim_targets: np.ndarray
    skeleton: Skeleton
    _model: object = field(repr=False)
    _coeffs: object = field(repr=False)

    @classmethod
    def create(cls, model, phenotype: Optional[Mapping[str, float]] = None) -> 'AnnyBody':
        """The body of ``phenotype`` (Anny parameters; missing ones 0.5) on ``model``
        (:func:`load_anny`)."""
        import torch
        pheno = _anny_params(phenotype or {})
        with torch.no_grad():
            inputs = model.get_tensor_inputs(None, pheno or None, None, None)
            coeffs = model._get_phenotype_blendshape_coefficients(*inputs[1:])
            rest = model.get_rest_model(coeffs)
        names = list(model.bone_labels)
        parents = np.array([-1] + [int(p) for p in model.bone_parents[1:]])
        poses = rest['rest_bone_poses'][0].double().numpy()
        heads = poses[:, :3, 3] @ ANNY_TO_PIPELINE.T
        rots = np.einsum('ij,bjk->bik', ANNY_TO_PIPELINE, poses[:, :3, :3])
        tails = rest['rest_bone_tails'][0].double().numpy() @ ANNY_TO_PIPELINE.T
        index = {n: i for i, n in enumerate(names)}
        missing = sorted(set(BONE_DRIVERS) - set(names))
        if missing:
            raise ValueError(f'the Anny rig lacks bones {missing}; expected rig="cmu_mb"')
        corr = np.tile(np.eye(3), (len(names), 1, 1))
        drivers = np.zeros(len(names), dtype=int)
        for name, (joint, target) in BONE_DRIVERS.items():
            b = index[name]
            drivers[b] = JOINT_INDEX[joint]
            if target is not None and not target.startswith('='):
                children = [c for c in range(len(names)) if parents[c] == b]
                tip = heads[children[0]] if children else tails[b]
                corr[b] = _min_rotation(tip - heads[b], REST_DIRECTIONS[JOINT_INDEX[target]])
        for name, (_, target) in BONE_DRIVERS.items():
            if target is not None and target.startswith('='):
                corr[index[name]] = corr[index[target[1:]]]
        weights = model.vertex_bone_weights if hasattr(model, 'vertex_bone_weights') else None
        vertex_bones = _dominant_bones(model, weights)
        faces = model.get_triangular_faces().numpy().astype(np.int64)
        tips = tails.copy()
        aim = np.full(len(names), -1)
        for name, (_, target) in BONE_DRIVERS.items():
            b = index[name]
            children = [c for c in range(len(names)) if parents[c] == b]
            if children:
                tips[b] = heads[children[0]]
            if target is not None and not target.startswith('='):
                aim[b] = JOINT_INDEX[target]
        rig_rest = to_convention(_rig_points(names, heads[None]))[0]
        skeleton = Skeleton.from_group_lengths(_group_lengths(rig_rest))
        return cls(pheno, names, parents, heads, rots, corr, drivers, faces, vertex_bones,
                   tips, aim, skeleton, model, coeffs)

    # ------------------------------------------------------------------------------------
    def rest_joints(self) -> np.ndarray:
        """(18, 3) the pipeline joints of the rest (A-)pose, pipeline axes."""
        return self._joints_from_heads(self.rest_heads[None])[0]

    def leg_length(self) -> float:
        """Mean hip-to-ankle distance through the knee at rest, metres."""
        j = self.rest_joints()
        out = []
        for s in ('left', 'right'):
            h, k, a = (j[JOINT_INDEX[f'{s}_{n}']] for n in ('hip', 'knee', 'ankle'))
            out.append(np.linalg.norm(k - h) + np.linalg.norm(a - k))
        return float(np.mean(out))

    def height(self) -> float:
        """Standing height of the rest mesh (top of the head to the soles), metres."""
        import torch
        with torch.no_grad():
            v = self._model.get_rest_model(self._coeffs)['rest_vertices'][0].numpy()
        return float(v[:, 2].max() - v[:, 2].min())

    def _rig_joints(self, heads: np.ndarray) -> np.ndarray:
        return _rig_points(self.bone_names, heads)

    def _joints_from_heads(self, heads: np.ndarray) -> np.ndarray:
        return to_convention(self._rig_joints(heads))

    def pose(self, global_rotations: np.ndarray, pelvis: np.ndarray,
             chunk: int = 64) -> PosedBody:
        """Pose the body.

        Args:
            global_rotations: (F, 18, 3, 3) world rotations of the pipeline joints relative to
                the T-pose (FK of a motion: ``motion.fk().global_rotations``).
            pelvis: (F, 3) where this body's pelvis (mean of the hip joints) goes, world.
            chunk: frames skinned per torch call.
        Returns:
            the posed mesh and joints, pipeline world frame.
        """
        import torch
        G = np.asarray(global_rotations, dtype=np.float64)
        pelvis = np.asarray(pelvis, dtype=np.float64)
        F = len(G)
        # The ground truth: the pipeline skeleton of this body, exactly.
        joints = self.skeleton_positions(G, pelvis)
        # World orientation of every bone: G_driver @ C_bone (pipeline axes), then the limb
        # bones re-aimed from their posed heads at the skeleton's next joint.
        Q = np.einsum('fbij,bjk->fbik', G[:, self.drivers], self.corrections)
        rest_pelvis = self._rig_joints(self.rest_heads[None])[0, JOINT_INDEX['pelvis']]
        heads = np.empty((F, len(self.bone_names), 3))
        # Root head so that the mean of the hips lands on ``pelvis``: the hips hang from the
        # root through bones that all take the pelvis rotation (LHipJoint, RHipJoint).
        heads[:, 0] = pelvis - np.einsum('fij,j->fi', Q[:, 0], rest_pelvis - self.rest_heads[0])
        for b in range(1, len(self.bone_names)):
            p = self.parents[b]
            heads[:, b] = heads[:, p] + np.einsum('fij,j->fi', Q[:, p],
                                                  self.rest_heads[b] - self.rest_heads[p])
            t = self.aim_targets[b]
            if t >= 0:
                u = np.einsum('fij,j->fi', Q[:, b], self.rest_tips[b] - self.rest_heads[b])
                Q[:, b] = np.einsum('fij,fjk->fik', _min_rotations(u, joints[:, t] - heads[:, b]),
                                    Q[:, b])
        W = np.einsum('fbij,bjk->fbik', Q, self.rest_rotations)
        A = ANNY_TO_PIPELINE
        D = np.einsum('ij,fbjk->fbik', A.T, W)  # back to Anny axes
        verts = np.empty((F, len(self.vertex_bones), 3), dtype=np.float32)
        with torch.no_grad():
            for s in range(0, F, chunk):
                e = min(F, s + chunk)
                delta = torch.zeros((e - s, len(self.bone_names), 4, 4), dtype=torch.float64)
                delta[..., :3, :3] = torch.from_numpy(D[s:e])
                delta[..., 3, 3] = 1.0
                delta[:, 0, :3, 3] = torch.from_numpy(heads[s:e, 0] @ A)
                out = _forward(self._model, delta.float(), self._coeffs)
                verts[s:e] = out['vertices'].numpy() @ A.T.astype(np.float32)
                heads[s:e] = out['bone_poses'][..., :3, 3].double().numpy() @ A.T
        return PosedBody(verts, joints, self._rig_joints(heads), heads)

    def skeleton_positions(self, global_rotations: np.ndarray,
                           pelvis: np.ndarray) -> np.ndarray:
        """(F, 18, 3) FK of the body's pipeline skeleton (:attr:`skeleton`) with the given
        global rotations, pelvis at ``pelvis``."""
        G = np.asarray(global_rotations, dtype=np.float64)
        off = self.skeleton.offsets
        P = np.empty(G.shape[:-3] + (NUM_JOINTS, 3))
        P[..., 0, :] = pelvis
        for j in range(1, NUM_JOINTS):
            p = PARENTS[j]
            P[..., j, :] = P[..., p, :] + np.einsum('...ij,j->...i', G[..., p, :, :], off[j])
        return P


def _rig_points(bone_names: Sequence[str], heads: np.ndarray) -> np.ndarray:
    """(..., 18, 3) the pipeline joints at the rig's points (:data:`JOINT_POINTS`)."""
    index = {n: i for i, n in enumerate(bone_names)}
    out = np.empty(heads.shape[:-2] + (NUM_JOINTS, 3))
    for j, name in enumerate(JOINT_NAMES):
        out[..., j, :] = np.mean([heads[..., index[b], :] for b in JOINT_POINTS[name]], axis=0)
    return out


def _group_lengths(joints: np.ndarray) -> np.ndarray:
    """(10,) bone-group lengths of one (18, 3) pose (symmetric pairs averaged)."""
    return np.array([np.mean([np.linalg.norm(joints[JOINT_INDEX[n]]
                                             - joints[PARENTS[JOINT_INDEX[n]]])
                              for n in names]) for _, names in BONE_GROUPS])


def _min_rotations(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(F, 3, 3) smallest rotations taking directions (F, 3) ``a`` onto ``b``."""
    return np.stack([_min_rotation(x, y) for x, y in zip(a, b)])


def to_convention(rig_joints: np.ndarray) -> np.ndarray:
    """(..., 18, 3) joints at the rig's points -> the training convention
    (:data:`CONVENTION_RATIOS`): hips, shoulders and head moved along their segments."""
    J = np.array(rig_joints, dtype=np.float64)
    ix = JOINT_INDEX

    def place(origin: np.ndarray, point: np.ndarray, length: np.ndarray) -> np.ndarray:
        d = point - origin
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        return origin + d / np.maximum(n, 1e-9) * length[..., None]

    pelvis, neck = J[..., ix['pelvis'], :], J[..., ix['neck'], :]
    for side in ('left', 'right'):
        hip, knee = J[..., ix[f'{side}_hip'], :], J[..., ix[f'{side}_knee'], :]
        thigh = np.linalg.norm(knee - hip, axis=-1)
        J[..., ix[f'{side}_hip'], :] = place(pelvis, hip, CONVENTION_RATIOS['hip_over_thigh']
                                             * thigh)
        sh, el = J[..., ix[f'{side}_shoulder'], :], J[..., ix[f'{side}_elbow'], :]
        arm = np.linalg.norm(el - sh, axis=-1)
        J[..., ix[f'{side}_shoulder'], :] = place(
            neck, sh, CONVENTION_RATIOS['clavicle_over_upper_arm'] * arm)
    spine = J[..., ix['spine'], :]
    neck_len = np.linalg.norm(neck - spine, axis=-1)
    J[..., ix['head'], :] = place(neck, J[..., ix['head'], :],
                                  CONVENTION_RATIOS['head_over_neck'] * neck_len)
    return J


def _forward(model, delta, coeffs):
    """Skinning with given blendshape coefficients (the phenotype is fixed per body)."""
    from anny.models.rigged_model import RiggedModelWithLinearBlendShapes
    return RiggedModelWithLinearBlendShapes.forward(model, delta, coeffs.expand(len(delta), -1))


def _dominant_bones(model, weights) -> np.ndarray:
    """(V,) index of the bone with the largest skinning weight of each vertex."""
    idx = getattr(model, 'vertex_bone_indices', None)
    w = getattr(model, 'vertex_bone_weights', None)
    if idx is None or w is None:
        raise ValueError('the Anny model exposes no skinning weights')
    idx = idx.numpy()
    w = w.numpy()
    return idx[np.arange(len(idx)), np.argmax(w, axis=1)]


def rotations_from_quaternions(q: np.ndarray) -> np.ndarray:
    """(..., 4) x, y, z, w -> (..., 3, 3)."""
    return np.asarray(quat_to_matrix(np.asarray(q, dtype=np.float64)))


def region_of_vertices(body: AnnyBody, head_details: bool = True) -> List[str]:
    """The clothing region (:data:`BONE_REGIONS`) of each vertex; with ``head_details``, the
    head's hair, eyebrows, eyes and lips as their own regions (:func:`head_detail_regions`)."""
    names = body.bone_names
    regions = [BONE_REGIONS.get(names[b], 'trunk') for b in body.vertex_bones]
    return head_detail_regions(body, regions) if head_details else regions


#: Head feature regions and what they cover, in metres for a head whose eye centres are
#: :data:`_REFERENCE_EYE_DISTANCE` apart (scaled with the body's own): the hairline above the
#: eyes at the forehead, how fast it drops behind the temples (m per m behind the eyes), the
#: eyebrows' band above the eyes (and how far behind the eyes' front it reaches), the iris
#: radius, the lips' half height, half width and depth.
HEAD_DETAIL_SIZES: Dict[str, float] = {
    'hairline_above_eyes': 0.062, 'hairline_temple_depth': 0.035, 'hairline_drop': 0.95,
    'brow_low': 0.011, 'brow_high': 0.021, 'brow_inner': 0.009, 'brow_outer': 0.052,
    'brow_depth': 0.03,
    'iris_radius': 0.0065, 'lip_half_height': 0.0045, 'lip_half_width': 0.02,
    'lip_depth': 0.012,
}
_REFERENCE_EYE_DISTANCE = 0.06
_EYE_LABELS = ('eye_front.L', 'eye_front.R')
_FACE_PART_VERTICES: Dict[str, np.ndarray] = {}


def _face_part_vertices(model) -> Dict[str, np.ndarray]:
    """Vertex indices of each eyeball's front and of the mouth cavity (Anny's body-part
    segmentation; cached, the topology is the same for every phenotype)."""
    if not _FACE_PART_VERTICES:
        from anny.face_segmentation import get_face_segmentation_mask
        faces = model.faces.numpy()
        parts = {label: np.unique(faces[get_face_segmentation_mask(model, [label]).numpy()])
                 for label in _EYE_LABELS + ('mouth_cavity',)}
        _FACE_PART_VERTICES.update(parts)        # all at once: never half filled
    return _FACE_PART_VERTICES


def head_detail_regions(body: AnnyBody, regions: Sequence[str]) -> List[str]:
    """``regions`` with the head's features marked, so that a rendered head has a face and
    hair as a real one does (a detector may tell front from back by them; measured in
    ``docs/rendering.md``):

    - ``eye_iris`` / ``eye_white``: the eyeballs' fronts, inside / outside
      ``iris_radius`` of the eye's axis;
    - ``brow``: a band above each eye;
    - ``lips``: a band at the mouth's height at the front of the face;
    - ``hair``: the scalp, above a hairline that runs ``hairline_above_eyes`` above the eyes
      at the forehead and drops behind the temples to the height of the mouth at the back.

    Measured on the rest mesh (pipeline axes: x forward, y left, z up), sizes
    (:data:`HEAD_DETAIL_SIZES`) scaled by the body's eye distance. Vertices not of the head
    keep their region.
    """
    import torch
    with torch.no_grad():
        v = body._model.get_rest_model(body._coeffs)['rest_vertices'][0].double().numpy()
    v = v @ ANNY_TO_PIPELINE.T
    parts = _face_part_vertices(body._model)
    out = np.array(regions, dtype=object)
    centres = [v[parts[lab]].mean(axis=0) for lab in _EYE_LABELS]
    eye = 0.5 * (centres[0] + centres[1])
    s = float(np.linalg.norm(centres[0] - centres[1])) / _REFERENCE_EYE_DISTANCE
    z = {k: val * s for k, val in HEAD_DETAIL_SIZES.items()}
    mouth_z = float(v[parts['mouth_cavity'], 2].mean())
    head = out == 'head'
    eyeballs = np.zeros(len(v), dtype=bool)
    for lab in _EYE_LABELS:
        eyeballs[parts[lab]] = True
    behind = eye[0] - v[:, 0]  # m behind the eyes (x forward)
    rel_z = v[:, 2] - eye[2]
    hairline = z['hairline_above_eyes'] - z['hairline_drop'] * np.maximum(
        0.0, behind - z['hairline_temple_depth'])
    hair = head & ~eyeballs & (rel_z > hairline) & (v[:, 2] > mouth_z)
    lateral = np.abs(v[:, 1] - eye[1])
    brow = (head & ~eyeballs & ~hair & (behind < z['brow_depth']) & (rel_z > z['brow_low'])
            & (rel_z < z['brow_high']) & (lateral > z['brow_inner']) & (lateral < z['brow_outer']))
    lips = (head & ~eyeballs & (behind < z['lip_depth'])
            & (np.abs(v[:, 2] - mouth_z) < z['lip_half_height'])
            & (np.abs(v[:, 1] - eye[1]) < z['lip_half_width']))
    out[hair], out[brow], out[lips] = 'hair', 'brow', 'lips'
    for lab, c in zip(_EYE_LABELS, centres):
        off = v[parts[lab]] - c
        radial = np.linalg.norm(off[:, 1:], axis=1)  # distance from the eye's forward axis
        out[parts[lab]] = np.where((off[:, 0] > 0) & (radial < z['iris_radius']),
                                   'eye_iris', 'eye_white')
    return out.tolist()


__all__: Sequence[str] = ('ANNY_TO_PIPELINE', 'AnnyBody', 'BONE_DRIVERS', 'JOINT_POINTS',
                          'PHENOTYPE_RANGES', 'PosedBody', 'default_cache_dir', 'load_anny',
                          'sample_phenotype')
