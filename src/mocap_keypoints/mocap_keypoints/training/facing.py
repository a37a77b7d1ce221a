"""Training and evaluating the facing classifier (:mod:`mocap_keypoints.facing`) on rendered
people (no ROS imports).

Data: every clip of ``mocap data render`` holds the video, the detector's keypoints of each
frame (BlazePose, run when the clip was rendered) and the true joints in the camera frame.
:func:`clip_crops` cuts the person out of every ``step``-th frame with the detector's
keypoints (:func:`~mocap_keypoints.facing.person_crop`, as the node does) and labels it with
the true facing: ``toward`` is minus the optical-axis component of the body's forward
direction (the cross product of the body's left axis, hips and shoulders, with its up axis,
pelvis to neck), +1 facing the camera, -1 facing away, 0 side on. Training uses the crops
with ``|toward| > margin`` as two classes.

Training (:func:`train`): Adam with a one-cycle schedule, batches drawn at random, augmented
with horizontal flips (a flipped image of a person facing the camera still faces it), a
random permutation of the colour channels, brightness and colour shifts and small
translations. Evaluation (:func:`evaluate_clips`): accuracy by true view on clips never
trained on, and the label check itself (:class:`~mocap_keypoints.facing.FacingCheck`) run
over each clip as the node runs it, scored with the rendered benchmark's leg-swap count
(:func:`mocap_core.render.evaluate.detector_swaps`) before and after.
"""

from __future__ import annotations

import csv
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from mocap_core.skeleton import JOINT_INDEX

from ..facing import (FacingCheck, FacingCheckParams, FacingNet, crops_to_tensor,
                      person_crop, save_weights, signed_width)

VIEWS = ('front', 'side', 'back')


def body_toward_camera(joints_camera: np.ndarray) -> np.ndarray:
    """(F, 18, 3) joints in the camera's optical frame (z forward) -> (F,) how much the body's
    front faces the camera: -forward_z, in [-1, 1] (see the module docstring)."""
    j = np.asarray(joints_camera, dtype=np.float64)
    left = (j[:, JOINT_INDEX['left_hip']] - j[:, JOINT_INDEX['right_hip']]
            + j[:, JOINT_INDEX['left_shoulder']] - j[:, JOINT_INDEX['right_shoulder']])
    up = j[:, JOINT_INDEX['neck']] - j[:, JOINT_INDEX['pelvis']]
    forward = np.cross(left, up)
    forward /= np.linalg.norm(forward, axis=1, keepdims=True) + 1e-9
    return -forward[:, 2]


@dataclass
class ClipCrops:
    """The crops of one clip: ``crops`` (N, 96, 48, 3) uint8, ``toward`` (N,), ``frames``
    (N,) frame numbers, ``width`` (N,) the detector labels' :func:`signed_width`."""

    crops: np.ndarray
    toward: np.ndarray
    frames: np.ndarray
    width: np.ndarray


def clip_crops(clip_dir: Path, step: int = 1) -> ClipCrops:
    """Crops of every ``step``-th frame of a rendered clip where the detector saw the person
    (see the module docstring)."""
    import cv2

    from mocap_core.render.clip import load_clip

    gt, _meta = load_clip(clip_dir)
    kp = gt['keypoints']
    toward = body_toward_camera(gt['joints_camera'])
    cap = cv2.VideoCapture(str(Path(clip_dir) / 'video.mp4'))
    crops, tw, frames, width = [], [], [], []
    f = -1
    try:
        while True:
            ok, image = cap.read()
            f += 1
            if not ok or f >= len(kp):
                break
            if f % step:
                continue
            crop = person_crop(image, kp[f])
            if crop is None:
                continue
            crops.append(crop)
            tw.append(toward[f])
            frames.append(f)
            width.append(signed_width(kp[f]))
    finally:
        cap.release()
    return ClipCrops(np.array(crops, dtype=np.uint8).reshape(-1, 96, 48, 3),
                     np.array(tw, dtype=np.float32), np.array(frames, dtype=np.int64),
                     np.array(width, dtype=np.float32))


def dataset_matches(path: Path, clip_dirs: Sequence[Path], step: int) -> bool:
    """Whether the crops file ``path`` was cut from exactly ``clip_dirs`` with ``step``."""
    try:
        with np.load(path) as z:
            return (int(z['step']) == int(step)
                    and z['clip_names'].tolist() == [Path(d).name for d in clip_dirs])
    except (OSError, KeyError, ValueError):
        return False


def build_dataset(clip_dirs: Sequence[Path], out: Path, step: int = 3,
                  progress: bool = True) -> Dict[str, int]:
    """Crops of all ``clip_dirs`` into one ``.npz`` (``crops``, ``toward``, ``clip`` (index
    into ``clip_names``), ``step``); returns counts."""
    from tqdm import tqdm

    crops, toward, clip = [], [], []
    for n, d in enumerate(tqdm(clip_dirs, desc='facing crops', unit='clip',
                               disable=not progress)):
        c = clip_crops(d, step)
        if len(c.crops):
            crops.append(c.crops)
            toward.append(c.toward)
            clip.append(np.full(len(c.crops), n, dtype=np.int32))
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix('.tmp.npz')
    np.savez(tmp, crops=np.concatenate(crops), toward=np.concatenate(toward),
             clip=np.concatenate(clip), step=np.int64(step),
             clip_names=np.array([Path(d).name for d in clip_dirs]))
    tmp.replace(out)
    return {'clips': len(clip_dirs), 'crops': int(sum(len(c) for c in crops))}


@dataclass
class TrainConfig:
    """Training settings of :func:`train`."""

    steps: int = 4000
    batch: int = 128
    lr: float = 3e-3
    #: crops with |toward| at most this (side on) are left out of training
    margin: float = 0.2
    seed: int = 0
    threads: int = 1


def augment(x, generator):
    """A batch (B, 3, H, W) in [0, 1], randomly flipped left-right, colour channels permuted,
    brightness scaled by 0.6-1.4, each channel shifted by up to +-0.1, and rolled by up to
    4 x 6 pixels (the same shift for the batch; what leaves one side comes in at the other)."""
    import torch

    b = len(x)
    flip = torch.rand(b, generator=generator) < 0.5
    x = torch.where(flip[:, None, None, None], x.flip(3), x)
    perm = torch.argsort(torch.rand(b, 3, generator=generator), dim=1)
    x = torch.gather(x, 1, perm[:, :, None, None].expand_as(x))
    x = (x * (0.6 + 0.8 * torch.rand(b, 1, 1, 1, generator=generator))
         + 0.2 * (torch.rand(b, 3, 1, 1, generator=generator) - 0.5))
    dx = int(torch.randint(-4, 5, (1,), generator=generator))
    dy = int(torch.randint(-6, 7, (1,), generator=generator))
    return torch.roll(x, (dy, dx), (2, 3)).clamp(0.0, 1.0)


def probabilities(net, crops: np.ndarray, batch: int = 512) -> np.ndarray:
    """(N, 96, 48, 3) uint8 -> (N,) probabilities of facing the camera (``net`` in eval
    mode)."""
    import torch

    out = []
    with torch.no_grad():
        for i in range(0, len(crops), batch):
            out.append(torch.sigmoid(net(crops_to_tensor(crops[i:i + batch]))).numpy())
    return np.concatenate(out) if out else np.zeros(0)


def view_accuracy(prob: np.ndarray, toward: np.ndarray) -> Dict[str, float]:
    """Share of right answers among crops facing the camera (toward > 0.5), facing away
    (< -0.5) and all with |toward| > 0.3."""
    right = (prob > 0.5) == (toward > 0)
    out = {}
    for name, sel in (('front', toward > 0.5), ('back', toward < -0.5),
                      ('all', np.abs(toward) > 0.3)):
        out[name] = float(right[sel].mean()) if sel.any() else float('nan')
    return out


def train(data: Path, run_dir: Path, config: TrainConfig,
          val: Optional[Tuple[np.ndarray, np.ndarray]] = None,
          log: Callable[[str], None] = print, progress: bool = True):
    """Train a :class:`~mocap_keypoints.facing.FacingNet` on the crops of ``data``
    (:func:`build_dataset`); ``val`` (crops, toward) is scored every 500 steps into
    ``run_dir/log.csv``. Returns the network (eval mode)."""
    import torch
    from tqdm import tqdm

    torch.set_num_threads(config.threads)
    torch.manual_seed(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    with np.load(data) as z:
        toward = z['toward']
        keep = np.abs(toward) > config.margin
        crops = z['crops']
        if not keep.all():
            crops = crops[keep]
        labels = (toward[keep] > 0).astype(np.float32)
    log(f'facing: {len(crops)} training crops ({labels.mean() * 100:.0f} % facing the '
        'camera)')
    x_all = torch.from_numpy(crops)  # uint8, converted per batch (keeps memory 1 byte/px)
    y_all = torch.from_numpy(labels)
    net = FacingNet()
    opt = torch.optim.Adam(net.parameters(), config.lr / 3)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, config.lr, total_steps=config.steps)
    run_dir.mkdir(parents=True, exist_ok=True)
    rows: List[Dict[str, float]] = []
    t0 = time.time()
    bar = tqdm(range(config.steps), desc='facing', unit='step', disable=not progress)
    for step in bar:
        idx = torch.randint(0, len(x_all), (config.batch,), generator=gen)
        x = augment(x_all[idx].permute(0, 3, 1, 2).float() / 255.0, gen)
        loss = torch.nn.functional.binary_cross_entropy_with_logits(net(x), y_all[idx])
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if (step + 1) % 500 == 0 or step + 1 == config.steps:
            row = {'step': step + 1, 'loss': loss.item(), 'seconds': time.time() - t0}
            if val is not None:
                net.eval()
                acc = view_accuracy(probabilities(net, val[0]), val[1])
                net.train()
                row.update({f'val_{k}': v for k, v in acc.items()})
            rows.append(row)
            bar.set_postfix(loss=f'{loss.item():.3f}')
            log('  '.join(f'{k} {v:.3f}' if isinstance(v, float) else f'{k} {v}'
                          for k, v in row.items()))
    with open(run_dir / 'log.csv', 'w', newline='') as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[-1]))
        w.writeheader()
        w.writerows(rows)
    net.eval()
    return net


def save(net, path: Path, config: TrainConfig, info: Dict) -> None:
    """Write the weights with the training settings and ``info`` (data, figures)."""
    save_weights(net, path, {'config': asdict(config), **info})


def check_clip(clip_dir: Path, classifier, params: FacingCheckParams) -> Dict[str, np.ndarray]:
    """Run :class:`FacingCheck` over one rendered clip's frames and the detector's keypoints
    (one person, as the node without a tracker), and score the leg labels before and after.

    Returns ``view`` (F,), ``before`` and ``after`` (F,) from
    :func:`~mocap_core.render.evaluate.detector_swaps` (1 mirrored, 0 right, -1 not scored),
    ``toward`` (F,), ``prob`` (F,) (NaN where no crop)."""
    import cv2

    from mocap_core.render.clip import load_clip
    from mocap_core.render.evaluate import detector_swaps

    gt, _meta = load_clip(clip_dir)
    kp = np.asarray(gt['keypoints'], dtype=np.float64)
    fps = float(gt['fps'])
    check = FacingCheck(_Recording(classifier), params)
    after = kp.copy()
    prob = np.full(len(kp), np.nan)
    cap = cv2.VideoCapture(str(Path(clip_dir) / 'video.mp4'))
    try:
        for f in range(len(kp)):
            ok, image = cap.read()
            if not ok:
                break
            check.classifier.last = math.nan
            out, _ = check.apply(image, kp[f:f + 1], None, f / fps)
            after[f] = out[0]
            prob[f] = check.classifier.last
    finally:
        cap.release()
    return {'view': np.asarray(gt['view']), 'before': detector_swaps(gt),
            'after': detector_swaps({**gt, 'keypoints': after}),
            'toward': body_toward_camera(gt['joints_camera']), 'prob': prob}


class _Recording:
    """A classifier that remembers its last probability (for :func:`check_clip` and
    :func:`video_check`)."""

    def __init__(self, classifier) -> None:
        self.classifier = classifier
        self.last = math.nan

    def probabilities(self, crops):
        p = self.classifier.probabilities(crops)
        if len(p):
            self.last = float(p[0])
        return p


def evaluate_clips(clip_dirs: Iterable[Path], classifier, params: FacingCheckParams,
                   progress: bool = True) -> Dict:
    """:func:`check_clip` over clips, pooled: accuracy by true view and the detector's leg
    swaps before and after the check, by view (percent of scored frames)."""
    from tqdm import tqdm

    res = {v: [0, 0, 0] for v in VIEWS + ('all',)}  # scored, swapped before, after
    acc = {v: [0, 0] for v in ('front', 'back', 'all')}
    changed = [0, 0]  # frames whose labels the check changed, right -> mirrored
    clips = list(clip_dirs)
    for d in tqdm(clips, desc='facing check', unit='clip', disable=not progress):
        r = check_clip(d, classifier, params)
        for v in VIEWS + ('all',):
            sel = np.ones(len(r['view']), bool) if v == 'all' else r['view'] == v
            scored = sel & (r['before'] >= 0) & (r['after'] >= 0)
            res[v][0] += int(scored.sum())
            res[v][1] += int((r['before'][scored] == 1).sum())
            res[v][2] += int((r['after'][scored] == 1).sum())
        seen = np.isfinite(r['prob'])
        right = (r['prob'] > 0.5) == (r['toward'] > 0)
        for name, sel in (('front', r['toward'] > 0.5), ('back', r['toward'] < -0.5),
                          ('all', np.abs(r['toward']) > 0.3)):
            acc[name][0] += int((sel & seen).sum())
            acc[name][1] += int((right & sel & seen).sum())
        changed[0] += int(((r['before'] == 0) & (r['after'] == 1)).sum())
        changed[1] += int(((r['before'] == 1) & (r['after'] == 0)).sum())
    return {
        'clips': len(clips),
        'accuracy': {k: (b / a if a else float('nan')) for k, (a, b) in acc.items()},
        'crops': {k: a for k, (a, _b) in acc.items()},
        'swaps_before': {k: (100.0 * b / a if a else float('nan'))
                         for k, (a, b, _c) in res.items()},
        'swaps_after': {k: (100.0 * c / a if a else float('nan'))
                        for k, (a, _b, c) in res.items()},
        'scored_frames': {k: a for k, (a, _b, _c) in res.items()},
        'fixed_frames': changed[1], 'broken_frames': changed[0],
        'params': asdict(params),
    }


def video_check(path: Path, classifier, params: FacingCheckParams,
                max_frames: Optional[int] = None) -> Dict:
    """The detector (BlazePose, one person, tracking) and the check over a real video, with
    no ground truth: per frame the detector labels' :func:`signed_width` and the network's
    probability. Returns counts of frames with the person seen, whose labels face the camera
    (width > ``params.min_width``) or turn away (< -min_width), the network's mean
    probability, frames exchanged, and (F,) arrays ``width``, ``prob``, ``exchanged``."""
    import cv2

    from ..detector import create_detector

    det = create_detector('blazepose', tracking=True)
    check = FacingCheck(_Recording(classifier), params)
    fps = 30.0
    width, prob, exch = [], [], []
    cap = cv2.VideoCapture(str(path))
    try:
        fps = cap.get(cv2.CAP_PROP_FPS) or fps
        f = 0
        while max_frames is None or f < max_frames:
            ok, image = cap.read()
            if not ok:
                break
            people = det.detect(image)
            kp = people[:1] if len(people) else np.zeros((1, 23, 3))
            check.classifier.last = math.nan
            _, ex = check.apply(image, kp, None, f / fps)
            width.append(signed_width(kp[0]))
            prob.append(check.classifier.last)
            exch.append(bool(ex[0]))
            f += 1
    finally:
        cap.release()
        det.close()
    w, p, e = np.array(width), np.array(prob), np.array(exch)
    seen = np.isfinite(w) & np.isfinite(p)
    return {'frames': len(w), 'scored': int(seen.sum()),
            'labels_facing': int((w[seen] > params.min_width).sum()),
            'labels_away': int((w[seen] < -params.min_width).sum()),
            'network_facing': int((p[seen] > 0.5).sum()),
            'mean_probability': float(np.mean(p[seen])) if seen.any() else float('nan'),
            'exchanged': int(e.sum()), 'width': w, 'prob': p, 'exchanged_frames': e}


__all__ = ['ClipCrops', 'TrainConfig', 'VIEWS', 'augment', 'body_toward_camera',
           'build_dataset', 'check_clip', 'clip_crops', 'evaluate_clips', 'probabilities',
           'dataset_matches', 'save', 'train', 'video_check', 'view_accuracy']
