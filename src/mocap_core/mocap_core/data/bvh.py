"""BVH motion-capture files: parsing and forward kinematics (no ROS imports).

Parsing (:func:`read_bvh`)
--------------------------
Any channel layout is accepted: every joint (root or not) may have position and rotation
channels in any number and order, and each joint may use its own Euler order. Keywords are
matched case-insensitively (``ROOT``/``Root``, ``JOINT``/``Joint``, ``End Site``/``End site``),
line endings may be LF, CRLF or CR, and any run of spaces/tabs separates tokens, so the CRLF
files of the CMU conversions and the tab/space mixes of the other sources all read the same.
``End Site`` blocks are kept as extra leaf points (:attr:`BVH.end_sites`); they have no
channels. A motion section with fewer complete frames than ``Frames:`` announces (a truncated
file) is read up to the last complete frame, with a warning.

Channel semantics (the usual ones, e.g. Blender's importer):

* rotation channels compose in the order they are listed, as *intrinsic* rotations:
  ``CHANNELS 3 Zrotation Xrotation Yrotation`` means ``L = Rz(z) @ Rx(x) @ Ry(y)`` (SciPy /
  :func:`mocap_core.rotations.euler_to_matrix` order ``'ZXY'``), angles in degrees; ``L`` maps
  the joint's frame to its parent's frame (column vectors);
* position channels **replace** the matching component of the joint's ``OFFSET`` (they are the
  joint's translation in its parent's frame). For the root this is the usual global position;
  for the Bandai Namco files, where every joint has 6 channels, the position channels repeat
  the offsets except on ``Hips``/``joint_Root``, which carry the translation (so the whole chain
  ``joint_Root`` -> ``Hips`` -> ... is always composed);
* FK: ``G_j = G_parent @ L_j``, ``p_j = p_parent + G_parent @ t_j``.

World frame (:func:`bvh_fk`)
----------------------------
BVH files are y-up and right-handed; in all the data used here the subject's rest pose faces
+z_bvh with its left side towards +x_bvh (e.g. the CMU ``LeftUpLeg`` offset has x > 0 and the
toes have z > 0). The pipeline world frame (docs/design.md §3) is z up, and the body frame is
x forward, y left. The conversion is the cyclic axis permutation (a proper rotation, det = +1)::

    (x, y, z)_world = (z, x, y)_bvh          i.e.  p_world = BVH_TO_WORLD @ p_bvh

so up (y_bvh) becomes +z, the rest-pose forward direction (+z_bvh) becomes +x and the subject's
left (+x_bvh) becomes +y: a subject in the BVH rest pose stands in the pipeline's body frame.
Global joint rotations are converted the same way on both sides, ``G_world = M G_bvh M^T``, so
an identity BVH rotation stays identity and a vector ``v`` given in BVH joint axes maps to the
world as ``G_world @ (M v)``.

Units are not stored in BVH files; :func:`bvh_fk` takes ``unit_scale`` (metres per file unit).
:func:`guess_unit_scale` infers it from the skeleton size when the format is unknown; the
retargeting module uses the documented unit of each known format and sanity-checks it with this
guess (see :mod:`mocap_core.data.retarget`).
"""

from __future__ import annotations

import io
import logging
import os
import re
import tarfile
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Iterator, List, Optional, Sequence, Tuple, Union

import numpy as np

from ..rotations import axis_angle_to_matrix, euler_to_matrix

__all__ = [
    'BVH', 'BVHError', 'EndSite', 'BVHPose', 'read_bvh', 'parse_bvh', 'iter_bvh_archive',
    'is_bvh_archive', 'list_bvh_sources', 'iter_bvh_sources', 'bvh_fk', 'skeleton_diameter',
    'guess_unit_scale', 'BVH_TO_WORLD', 'UNIT_SCALES', 'CMU_ASF_UNIT',
]

_LOG = logging.getLogger(__name__)

#: Rotation taking BVH (y-up: x left, y up, z forward in the rest pose) coordinates to the
#: pipeline world frame (z up): ``(x, y, z)_world = (z, x, y)_bvh``.
BVH_TO_WORLD: np.ndarray = np.array([[0.0, 0.0, 1.0],
                                     [1.0, 0.0, 0.0],
                                     [0.0, 1.0, 0.0]])
BVH_TO_WORLD.setflags(write=False)

#: One CMU ASF length unit in metres: the ASF files declare ``length 0.45`` with inches as the
#: base unit, i.e. 1 unit = (1 / 0.45) inch.
CMU_ASF_UNIT: float = 0.0254 / 0.45

#: Candidate units (metres per file unit) considered by :func:`guess_unit_scale`.
UNIT_SCALES = {'m': 1.0, 'cm': 0.01, 'mm': 0.001, 'inch': 0.0254, 'cmu_asf': CMU_ASF_UNIT}

_AXES = 'XYZ'


class BVHError(ValueError):
    """A BVH file could not be parsed (the message says where and why)."""


@dataclass(frozen=True)
class EndSite:
    """An ``End Site`` leaf point: ``offset`` (3,) in the frame of joint ``parent``, file units."""

    parent: int
    offset: np.ndarray


@dataclass(eq=False)
class BVH:
    """A parsed BVH file.

    Attributes:
        joint_names: (J,) joint names in file (depth-first) order; index 0 is the root.
        parents: (J,) parent index of each joint, -1 for the root; ``parents[j] < j``.
        offsets: (J, 3) float64 ``OFFSET`` of each joint in its parent's frame, file units.
        channels: per joint, the channel names in file order, normalised to
            ``'Xposition' ... 'Zrotation'`` (3 or 6 per joint in the data here, but any number
            and order is accepted).
        end_sites: the ``End Site`` leaf points (no channels).
        frame_time: seconds per frame.
        motion: (F, C) float64 channel values; joint ``j``'s channels are the columns
            ``channel_start[j] : channel_start[j] + len(channels[j])``. Angles in degrees.
        name: a label (file or archive-member name) for messages.
    """

    joint_names: Tuple[str, ...]
    parents: Tuple[int, ...]
    offsets: np.ndarray
    channels: Tuple[Tuple[str, ...], ...]
    end_sites: Tuple[EndSite, ...]
    frame_time: float
    motion: np.ndarray
    name: str = ''
    channel_start: Tuple[int, ...] = field(init=False)

    def __post_init__(self) -> None:
        J = len(self.joint_names)
        self.offsets = np.asarray(self.offsets, dtype=np.float64).reshape(J, 3)
        self.motion = np.asarray(self.motion, dtype=np.float64)
        if len(self.parents) != J or len(self.channels) != J:
            raise BVHError(f'{self.name}: inconsistent joint tables')
        starts, c = [], 0
        for ch in self.channels:
            starts.append(c)
            c += len(ch)
        self.channel_start = tuple(starts)
        if self.motion.ndim != 2 or self.motion.shape[1] != c:
            raise BVHError(f'{self.name}: motion has shape {self.motion.shape}, expected (F, {c})')

    # -- sizes ---------------------------------------------------------------------------------
    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def num_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def num_channels(self) -> int:
        return int(self.motion.shape[1])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time if self.frame_time > 0 else float('nan')

    def joint_index(self, name: str) -> int:
        """Index of a joint by name (exact match first, then case-insensitive)."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            low = [n.lower() for n in self.joint_names]
            if name.lower() in low:
                return low.index(name.lower())
        raise KeyError(f'{self.name}: no joint {name!r}; joints: {", ".join(self.joint_names)}')

    def joint_channels(self, j: int) -> np.ndarray:
        """(F, n_j) motion columns of joint ``j``."""
        s = self.channel_start[j]
        return self.motion[:, s:s + len(self.channels[j])]

    def rotation_order(self, j: int) -> str:
        """Rotation channel axes of joint ``j`` in file order, e.g. ``'ZYX'`` ('' if none)."""
        return ''.join(c[0] for c in self.channels[j] if c.endswith('rotation'))

    def children(self, j: int) -> List[int]:
        return [k for k, p in enumerate(self.parents) if p == j]

    def end_sites_of(self, j: int) -> List[EndSite]:
        return [e for e in self.end_sites if e.parent == j]

    def slice_frames(self, frames: Union[slice, Sequence[int], np.ndarray]) -> 'BVH':
        """Copy with a subset of the frames (same skeleton)."""
        return BVH(self.joint_names, self.parents, self.offsets, self.channels, self.end_sites,
                   self.frame_time, self.motion[frames], self.name)

    def __repr__(self) -> str:
        return (f'BVH({self.name!r}, joints={self.num_joints}, end_sites={len(self.end_sites)}, '
                f'frames={self.num_frames}, frame_time={self.frame_time:.6g})')


# ---------------------------------------------------------------------------------------------
# parsing
# ---------------------------------------------------------------------------------------------
_CHANNEL_RE = re.compile(r'^([xyz])(position|rotation)$', re.IGNORECASE)
_MOTION_RE = re.compile(r'^[ \t]*MOTION[ \t]*$', re.IGNORECASE | re.MULTILINE)
_FRAMES_RE = re.compile(r'Frames\s*:\s*(\d+)', re.IGNORECASE)
_FRAME_TIME_RE = re.compile(r'Frame\s*Time\s*:\s*([-+0-9.eE]+)', re.IGNORECASE)


def _norm_channel(tok: str, where: str) -> str:
    m = _CHANNEL_RE.match(tok)
    if not m:
        raise BVHError(f'{where}: unknown channel {tok!r} (expected X/Y/Z position/rotation)')
    return m.group(1).upper() + m.group(2).lower()


def parse_bvh(text: str, name: str = '<string>') -> BVH:
    """Parse the text of a BVH file (see the module docstring for the accepted syntax)."""
    text = text.replace('\r\n', '\n').replace('\r', '\n')
    if text.startswith('\ufeff'):
        text = text[1:]
    m = _MOTION_RE.search(text)
    if m is None:
        raise BVHError(f'{name}: no MOTION section')
    header, motion_text = text[:m.start()], text[m.end():]

    toks = header.split()
    if not toks or toks[0].upper() != 'HIERARCHY':
        raise BVHError(f'{name}: file does not start with HIERARCHY')
    names: List[str] = []
    parents: List[int] = []
    offsets: List[np.ndarray] = []
    channels: List[Tuple[str, ...]] = []
    end_sites: List[EndSite] = []
    # stack entries: joint index, or ('end', end-site index) for End Site blocks
    stack: List[object] = []
    pending: Optional[object] = None   # node declared, waiting for its '{'
    i, n = 1, len(toks)

    def where() -> str:
        return f'{name}: hierarchy token {i}'

    def read_floats(k: int) -> np.ndarray:
        nonlocal i
        if i + k > n:
            raise BVHError(f'{where()}: unexpected end of hierarchy')
        try:
            vals = np.array([float(t) for t in toks[i:i + k]])
        except ValueError:
            raise BVHError(f'{where()}: expected {k} numbers, got {toks[i:i + k]}') from None
        i += k
        return vals

    def current_joint() -> int:
        if not stack or not isinstance(stack[-1], int):
            raise BVHError(f'{where()}: OFFSET/CHANNELS outside a joint block')
        return stack[-1]

    while i < n:
        tok = toks[i]
        up = tok.upper()
        if up in ('ROOT', 'JOINT'):
            i += 1
            parts = []
            while i < n and toks[i] != '{':
                parts.append(toks[i])
                i += 1
            if not parts:
                raise BVHError(f'{where()}: {tok} without a name')
            if up == 'ROOT' and stack:
                raise BVHError(f'{where()}: ROOT inside another joint')
            if up == 'JOINT' and not stack:
                raise BVHError(f'{where()}: JOINT outside the ROOT block')
            if up == 'ROOT' and names:
                raise BVHError(f'{name}: more than one ROOT (only one skeleton per file)')
            parent = -1 if up == 'ROOT' else current_joint()
            names.append(' '.join(parts))
            parents.append(parent)
            offsets.append(np.zeros(3))
            channels.append(())
            pending = len(names) - 1
        elif up == 'END':
            i += 1
            while i < n and toks[i] != '{':   # 'Site'
                i += 1
            end_sites.append(EndSite(current_joint(), np.zeros(3)))
            pending = ('end', len(end_sites) - 1)
        elif tok == '{':
            i += 1
            if pending is None:
                raise BVHError(f'{where()}: unexpected {{')
            stack.append(pending)
            pending = None
        elif tok == '}':
            i += 1
            if not stack:
                raise BVHError(f'{where()}: unbalanced }}')
            stack.pop()
        elif up == 'OFFSET':
            i += 1
            off = read_floats(3)
            top = stack[-1] if stack else None
            if isinstance(top, tuple):
                end_sites[top[1]] = EndSite(end_sites[top[1]].parent, off)
            else:
                offsets[current_joint()] = off
        elif up == 'CHANNELS':
            i += 1
            j = current_joint()
            try:
                k = int(toks[i])
            except (IndexError, ValueError):
                raise BVHError(f'{where()}: CHANNELS without a count') from None
            i += 1
            if i + k > n:
                raise BVHError(f'{where()}: unexpected end of hierarchy in CHANNELS')
            channels[j] = tuple(_norm_channel(t, where()) for t in toks[i:i + k])
            i += k
        else:
            raise BVHError(f'{where()}: unexpected token {tok!r}')
    if stack:
        raise BVHError(f'{name}: hierarchy ends inside a block (missing }})')
    if not names:
        raise BVHError(f'{name}: no joints')

    fm = _FRAMES_RE.search(motion_text)
    tm = _FRAME_TIME_RE.search(motion_text)
    if fm is None or tm is None:
        raise BVHError(f'{name}: MOTION section lacks "Frames:" or "Frame Time:"')
    num_frames = int(fm.group(1))
    frame_time = float(tm.group(1))
    if not frame_time > 0:
        raise BVHError(f'{name}: Frame Time must be positive, got {frame_time}')
    data_text = motion_text[max(fm.end(), tm.end()):]
    # the rest of the Frame Time line is not data
    data_text = data_text[data_text.find('\n') + 1:] if '\n' in data_text else ''
    C = sum(len(c) for c in channels)
    motion = _parse_motion(data_text, num_frames, C, name)
    return BVH(tuple(names), tuple(parents), np.stack(offsets), tuple(channels),
               tuple(end_sites), frame_time, motion, name)


def _parse_motion(data_text: str, num_frames: int, C: int, name: str) -> np.ndarray:
    if C == 0:
        return np.zeros((num_frames, 0))
    try:
        flat = np.array(data_text.split(), dtype=np.float64)
    except ValueError:
        flat = None
    if flat is not None and flat.size == num_frames * C:
        motion = flat.reshape(num_frames, C)
    else:
        # slow path: line by line, keep complete lines only
        rows = []
        bad = 0
        for line in data_text.split('\n'):
            parts = line.split()
            if not parts:
                continue
            try:
                vals = [float(p) for p in parts]
            except ValueError:
                bad += 1
                continue
            if len(vals) != C:
                bad += 1
                continue
            rows.append(vals)
        motion = np.array(rows, dtype=np.float64).reshape(-1, C)
        if motion.shape[0] > num_frames:
            motion = motion[:num_frames]
        msg = (f'{name}: header announces {num_frames} frames of {C} channels; read '
               f'{motion.shape[0]} complete frames ({bad} malformed lines skipped)')
        if motion.shape[0] == 0:
            raise BVHError(msg)
        warnings.warn(msg, stacklevel=3)
    if not np.all(np.isfinite(motion)):
        raise BVHError(f'{name}: motion data contains NaN or inf')
    return motion


def read_bvh(source: Union[str, os.PathLike, IO, bytes], name: Optional[str] = None) -> BVH:
    """Read a BVH file.

    Args:
        source: a path, an open file object (text or binary), the BVH text itself (a string
            starting with ``HIERARCHY``), or its bytes.
        name: label used in messages (default: the path or ``'<string>'``).
    """
    if isinstance(source, bytes):
        return parse_bvh(source.decode('utf-8', errors='replace'), name or '<bytes>')
    if isinstance(source, str) and source.lstrip('\ufeff \t\r\n')[:9].upper() == 'HIERARCHY':
        return parse_bvh(source, name or '<string>')
    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        with open(path, 'rb') as f:
            data = f.read()
        return parse_bvh(data.decode('utf-8', errors='replace'), name or str(path))
    if hasattr(source, 'read'):
        data = source.read()
        if isinstance(data, bytes):
            data = data.decode('utf-8', errors='replace')
        return parse_bvh(data, name or str(getattr(source, 'name', '<file>')))
    raise TypeError(f'read_bvh: unsupported source type {type(source).__name__}')


def iter_bvh_archive(path: Union[str, os.PathLike], pattern: Optional[str] = None,
                     on_error: str = 'warn') -> Iterator[Tuple[str, BVH]]:
    """Yield ``(member name, BVH)`` for every ``.bvh`` member of a tar archive, in place.

    The archive (``.tar``, ``.tar.gz``, ``.tar.xz``, ...) is streamed once in member order,
    nothing is unpacked to disk. ``pattern`` (a regular expression searched in the member name)
    selects members. A member that does not parse is skipped with a warning
    (``on_error='warn'``) or raises (``on_error='raise'``).
    """
    if on_error not in ('warn', 'raise'):
        raise ValueError("on_error must be 'warn' or 'raise'")
    rx = re.compile(pattern) if pattern else None
    with tarfile.open(path, 'r|*') as tar:
        for member in tar:
            if not member.isfile() or not member.name.lower().endswith('.bvh'):
                continue
            if rx is not None and not rx.search(member.name):
                continue
            f = tar.extractfile(member)
            if f is None:
                continue
            try:
                bvh = read_bvh(io.BytesIO(f.read()), name=member.name)
            except BVHError as e:
                if on_error == 'raise':
                    raise
                warnings.warn(f'{path}: skipping {member.name}: {e}', stacklevel=2)
                continue
            yield member.name, bvh


_ARCHIVE_SUFFIXES = ('.tar', '.tar.gz', '.tgz', '.tar.xz', '.txz', '.tar.bz2', '.tbz2')


def is_bvh_archive(path: Union[str, os.PathLike]) -> bool:
    """True for a tar archive name (``.tar``, ``.tar.gz``, ``.tar.xz``, ...)."""
    return str(path).lower().endswith(_ARCHIVE_SUFFIXES)


def list_bvh_sources(paths: Union[str, os.PathLike, Sequence[Union[str, os.PathLike]]]
                     ) -> List[Path]:
    """Expand files and directories (searched recursively, sorted) into the ``.bvh`` files and
    tar archives they contain."""
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    out: List[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out.extend(q for q in sorted(p.rglob('*'))
                       if q.is_file() and (q.suffix.lower() == '.bvh' or is_bvh_archive(q)))
        elif p.exists():
            out.append(p)
        else:
            raise FileNotFoundError(f'no such BVH file, archive or directory: {p}')
    return out


def iter_bvh_sources(paths: Union[str, os.PathLike, Sequence[Union[str, os.PathLike]]],
                     on_error: str = 'warn') -> Iterator[Tuple[str, BVH]]:
    """Yield ``(name, BVH)`` for every clip under ``paths`` (``.bvh`` files, tar archives,
    directories of either). Archive members are named ``<archive>:<member>``."""
    for p in list_bvh_sources(paths):
        if is_bvh_archive(p):
            for member, bvh in iter_bvh_archive(p, on_error=on_error):
                yield f'{p}:{member}', bvh
        else:
            try:
                yield str(p), read_bvh(p)
            except BVHError as e:
                if on_error == 'raise':
                    raise
                warnings.warn(f'skipping {p}: {e}', stacklevel=2)


# ---------------------------------------------------------------------------------------------
# forward kinematics
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BVHPose:
    """World-frame FK of a BVH clip (pipeline world frame: z up, metres).

    Attributes:
        positions: (F, J, 3) joint positions.
        rotations: (F, J, 3, 3) global joint orientations, ``M G_bvh M^T`` (see module doc).
        end_site_positions: (F, E, 3) positions of the ``End Site`` points.
        unit_scale: metres per file unit used.
    """

    positions: np.ndarray
    rotations: np.ndarray
    end_site_positions: np.ndarray
    unit_scale: float


def _local_rotations(bvh: BVH, j: int, motion: np.ndarray) -> Optional[np.ndarray]:
    """(F, 3, 3) local rotation of joint ``j`` from its rotation channels, or None."""
    s = bvh.channel_start[j]
    axes, cols = [], []
    for k, ch in enumerate(bvh.channels[j]):
        if ch.endswith('rotation'):
            axes.append(ch[0])
            cols.append(s + k)
    if not axes:
        return None
    angles = np.deg2rad(motion[:, cols])
    order = ''.join(axes)
    if len(order) == 3 and order[0] != order[1] and order[1] != order[2]:
        return euler_to_matrix(angles, order)          # intrinsic (upper case): Ra Rb Rc
    R = None
    for k, a in enumerate(axes):                       # any other count: compose in order
        v = np.zeros((angles.shape[0], 3))
        v[:, _AXES.index(a)] = angles[:, k]
        Rk = axis_angle_to_matrix(v)
        R = Rk if R is None else R @ Rk
    return R


def _local_translations(bvh: BVH, j: int, motion: np.ndarray) -> np.ndarray:
    """(F, 3) translation of joint ``j`` in its parent's frame (offset, position channels
    replacing their components)."""
    t = np.broadcast_to(bvh.offsets[j], (motion.shape[0], 3)).copy()
    s = bvh.channel_start[j]
    for k, ch in enumerate(bvh.channels[j]):
        if ch.endswith('position'):
            t[:, _AXES.index(ch[0])] = motion[:, s + k]
    return t


def bvh_fk(bvh: BVH, unit_scale: Optional[float] = None,
           frames: Union[None, slice, Sequence[int], np.ndarray] = None) -> BVHPose:
    """Forward kinematics of a BVH clip in the pipeline world frame (z up), metres.

    Args:
        bvh: the parsed file.
        unit_scale: metres per file unit (e.g. 0.01 for centimetres); ``None`` uses
            :func:`guess_unit_scale`.
        frames: optional frame selection (slice or indices); default all frames.
    """
    if unit_scale is None:
        unit_scale = guess_unit_scale(bvh)
        _LOG.debug('%s: guessed unit %g m', bvh.name, unit_scale)
    motion = bvh.motion if frames is None else bvh.motion[frames]
    F, J = motion.shape[0], bvh.num_joints
    G = np.empty((F, J, 3, 3))
    P = np.empty((F, J, 3))
    eye = np.broadcast_to(np.eye(3), (F, 3, 3))
    for j in range(J):
        L = _local_rotations(bvh, j, motion)
        t = _local_translations(bvh, j, motion)
        p = bvh.parents[j]
        if p < 0:
            G[:, j] = eye if L is None else L
            P[:, j] = t
        else:
            G[:, j] = G[:, p] if L is None else G[:, p] @ L
            P[:, j] = P[:, p] + np.einsum('fab,fb->fa', G[:, p], t)
    E = len(bvh.end_sites)
    PE = np.empty((F, E, 3))
    for e, site in enumerate(bvh.end_sites):
        PE[:, e] = P[:, site.parent] + G[:, site.parent] @ site.offset
    M = BVH_TO_WORLD
    return BVHPose(positions=unit_scale * P @ M.T,
                   rotations=M @ G @ M.T,
                   end_site_positions=unit_scale * PE @ M.T,
                   unit_scale=float(unit_scale))


# ---------------------------------------------------------------------------------------------
# units
# ---------------------------------------------------------------------------------------------
#: Typical length (m) of the longest path between two points of a human skeleton (hand or
#: fingertip to toe, through the spine): about 1.1-1.2 x the standing height.
_TYPICAL_SKELETON_DIAMETER_M = 2.0


def skeleton_diameter(bvh: BVH) -> float:
    """Length (file units) of the longest path between two joints/end sites along the bones.

    Pose independent. Edges whose translation is animated (the root's global translation,
    Bandai Namco's ``Hips`` under ``joint_Root``) are not bones and count as zero; constant
    position channels count with their value (they replace the offset).
    """
    J = bvh.num_joints
    lengths = np.zeros(J)
    for j in range(1, J):
        if any(c.endswith('position') for c in bvh.channels[j]):
            t = _local_translations(bvh, j, bvh.motion[:min(bvh.num_frames, 200)])
            if t.shape[0] and np.ptp(t, axis=0).max() > 1e-6 * max(1.0, np.abs(t).max()):
                continue
            lengths[j] = np.linalg.norm(t[0]) if t.shape[0] else np.linalg.norm(bvh.offsets[j])
        else:
            lengths[j] = np.linalg.norm(bvh.offsets[j])
    # graph with end sites as extra nodes; diameter of a tree = two-pass farthest search
    nodes = J + len(bvh.end_sites)
    adj: List[List[Tuple[int, float]]] = [[] for _ in range(nodes)]
    for j in range(1, J):
        adj[j].append((bvh.parents[j], lengths[j]))
        adj[bvh.parents[j]].append((j, lengths[j]))
    for e, site in enumerate(bvh.end_sites):
        w = float(np.linalg.norm(site.offset))
        adj[J + e].append((site.parent, w))
        adj[site.parent].append((J + e, w))

    def farthest(src: int) -> Tuple[int, float]:
        dist = [-1.0] * nodes
        dist[src] = 0.0
        todo = [src]
        while todo:
            a = todo.pop()
            for b, w in adj[a]:
                if dist[b] < 0:
                    dist[b] = dist[a] + w
                    todo.append(b)
        k = int(np.argmax(dist))
        return k, dist[k]

    far, _ = farthest(0)
    return float(farthest(far)[1])


def guess_unit_scale(bvh: BVH) -> float:
    """Guess the file's length unit (metres per unit) from the size of the skeleton.

    The candidate whose unit makes :func:`skeleton_diameter` (hand to toe along the bones,
    about 2 m for an adult) closest to 2 m on a log scale is chosen among
    :data:`UNIT_SCALES` (m, cm, mm, inch, CMU ASF unit). Neighbouring candidates differ by at
    least a factor 2.2, so adults are unambiguous; a child recorded in inches could be taken for
    CMU ASF units, which is why the retargeting prefers each known format's documented unit and
    only uses this guess as a check and for unknown formats.
    """
    d = skeleton_diameter(bvh)
    if not d > 0:
        raise BVHError(f'{bvh.name}: skeleton has zero size, cannot infer its unit')
    best = min(UNIT_SCALES.values(),
               key=lambda s: abs(np.log(d * s / _TYPICAL_SKELETON_DIAMETER_M)))
    return float(best)
