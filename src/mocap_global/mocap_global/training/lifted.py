"""GMR inputs as the pipeline really feeds them: the shipped lifter's local poses of each
training clip (no ROS imports).

GMR was trained on ground-truth local poses plus an assumed noise model. The lifter's output
differs in ways the noise model does not cover: seen from behind, a walker's stride along
the viewing direction comes out about half as long, and GMR then predicts walking on the
spot (docs/global.md, the real moving-camera walk). Here every training clip is seen by
``cameras`` random static cameras around it (the lifter's own camera sampler: any azimuth,
so front, side and back views), its joints are put where the real detector puts its
keypoints (``DetectorPlacement``) with the detector-like corruption (dropped points, jitter),
and the shipped windowed MotioNet lifts the whole clip, in the node's virtual camera
(``virtual_camera``). The lifter's local rotations and
bone-group lengths are stored per clip and camera, frame-aligned with the clip, and used as
the network input of a share of the training windows (``Augmentation.lifted_prob``); the
targets stay the ground truth.

The result is cached in ``~/.cache/mocap/gmr_lifted/<key>.npz`` (the key: clip names, frame
counts, cameras, seed and the lifter weights' size and time), so a rerun or the next session
reuses it; a missing cache is remade in about a minute.
"""

from __future__ import annotations

import hashlib
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence

import numpy as np

from mocap_core.data.motion import Motion

CACHE_DIR = Path.home() / '.cache' / 'mocap' / 'gmr_lifted'
#: Longest piece lifted at once (frames); longer clips are lifted piece by piece.
PIECE = 900


@dataclass
class LiftedClip:
    """The lifter's view of one clip: ``rotations`` (C, T, J, 4) x, y, z, w local rotations
    (row 0, the root, in the camera frame: GMR does not use it), ``lengths`` (C, G) bone-group
    lengths (m), for C cameras and the clip's T frames."""

    rotations: np.ndarray
    lengths: np.ndarray


def _key(motions: Sequence[Motion], cameras: int, seed: int, weights: Path,
         virtual_camera: bool = False) -> str:
    h = hashlib.sha1()
    for m in motions:
        h.update(f'{m.name}:{m.num_frames};'.encode())
    st = weights.stat()
    h.update(f'{cameras}:{seed}:{st.st_size}:{int(st.st_mtime)}'.encode())
    if virtual_camera:                 # keys made before the option stay valid
        h.update(b':virtual_camera')
    return h.hexdigest()[:16]


def lift_clips(motions: Sequence[Motion], cameras: int = 2, seed: int = 0,
               cache_dir: Optional[Path] = CACHE_DIR, progress: bool = True,
               device: str = 'cpu') -> List[LiftedClip]:
    """The shipped lifter's local poses of every clip seen by ``cameras`` random cameras
    (module docstring); cached in ``cache_dir`` (None: no cache)."""
    import torch
    from tqdm import tqdm

    from mocap_core.data.detector_placement import PLACEMENT_PATH, DetectorPlacement
    from mocap_core.data.synth2d import Corruption
    from mocap_lifter.online import DEFAULT_VIRTUAL_CAMERA
    from mocap_lifter.training.evaluate import lift
    from mocap_lifter.training.samples import Augmentation as LifterAugmentation
    from mocap_lifter.training.samples import make_sample
    from mocap_lifter.weights import default_weights, load_weights

    weights = default_weights('windowed')
    path = None
    if cache_dir is not None:
        path = Path(cache_dir) / \
            f'{_key(motions, cameras, seed, weights, DEFAULT_VIRTUAL_CAMERA)}.npz'
        if path.exists():
            with np.load(path) as z:
                rot, lengths, offsets = z['rotations'], z['lengths'], z['offsets']
            return [LiftedClip(rot[:, offsets[i]:offsets[i + 1]], lengths[:, i])
                    for i in range(len(motions))]
    model = load_weights(weights, device).eval()
    aug = LifterAugmentation(flip_prob=0.0, bone_scale=0.0, global_scale=0.0,
                             corruption=Corruption(), clean_prob=0.0,
                             placement=DetectorPlacement.load(PLACEMENT_PATH),
                             placement_prob=1.0)
    out: List[LiftedClip] = []
    with torch.no_grad():
        for m in tqdm(motions, desc='lifting the training clips', unit='clip',
                      disable=not progress):
            rng = np.random.default_rng([seed, zlib.crc32(m.name.encode())])
            rots, lens = [], []
            for _ in range(cameras):
                pieces, plen = [], []
                for s0 in range(0, m.num_frames, PIECE):
                    n = min(PIECE, m.num_frames - s0)
                    if n < 2:        # a one-frame tail: repeat the last lifted frame
                        pieces.append(pieces[-1][-1:])
                        continue
                    s = make_sample(m, s0, n, rng, aug)
                    res = lift(model, s['features'], s['root_2d'], s['scale'], device,
                               virtual_camera=DEFAULT_VIRTUAL_CAMERA)
                    pieces.append(res['rotations'])
                    plen.append(res['lengths'])
                rots.append(np.concatenate(pieces))
                lens.append(np.mean(plen, axis=0))
            out.append(LiftedClip(np.stack(rots).astype(np.float32),
                                  np.stack(lens).astype(np.float32)))
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        offsets = np.concatenate([[0], np.cumsum([c.rotations.shape[1] for c in out])])
        tmp = path.with_suffix('.tmp.npz')
        np.savez(tmp, rotations=np.concatenate([c.rotations for c in out], axis=1),
                 lengths=np.stack([c.lengths for c in out], axis=1), offsets=offsets)
        tmp.replace(path)
    return out
