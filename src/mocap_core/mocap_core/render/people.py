"""Rendered videos of several people, with the truth of who is who (no ROS imports).

The scenes of :mod:`mocap_core.data.multi_person` (recorded clips placed so that their paths
cross in front of a static camera, one person hiding another, people entering and leaving)
are rendered as video: every actor is its own Anny body (its own phenotype and clothes,
:func:`~mocap_core.render.clip.place_body`), all in one room, seen by the scene's camera. The
keypoint node then runs on the video as on any other (``mocap process``), so its detector
and tracker are judged on images they were never tuned on, unlike the keypoint scenes of
``mocap bench people``, which the tracker's parameters were chosen on.

:func:`render_people` writes ``video.mp4``, ``data.npz`` and ``meta.json`` into a folder;
:func:`match_rows` tells which actor each detected row is (by the rendered bodies' own mesh
keypoints); :func:`score_people_clip` scores the keypoint cloud of a ``mocap process`` run
with :func:`~mocap_core.data.multi_person.identity_metrics` (identity switches, fragments,
coverage, ids per actor) plus detection recall and the 2D error per person.

``data.npz`` (F frames, A actors): ``keypoints_mesh`` (F, A, 23, 3) each body's mesh
keypoints projected (u px, v px, 1 inside the image, else 0; all 0 while the actor is
absent); ``present`` (F, A) bool; ``depth`` (F, A) distance of the pelvis from the camera (m,
inf while absent); ``joints_camera`` (F, A, 18, 3) each body's pipeline joints in the optical
frame (m, NaN while absent); ``heights_m`` (A,); ``K`` (3, 3); ``image_size`` (2,); ``fps`` ().
"""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np

from ..camera import project_pinhole
from ..skeleton import NUM_KEYPOINTS

#: Bump when the output of :func:`render_people` changes meaning.
PEOPLE_FORMAT = 1

#: A detected row is an actor when the median distance of their keypoints is below this
#: fraction of the actor's height in the image.
MATCH_FRACTION = 0.15

#: :func:`find_delays` counts appearances (frames in a row where an actor is in the picture
#: and not hidden) of at least this many frames (half a second at 30 fps).
MIN_APPEARANCE_FRAMES = 15


def render_people(actors: Sequence, frames: int, camera, out_dir: Path, seed: int,
                  model=None, progress: Optional[Callable[[int], None]] = None,
                  scene: str = '', head_details: bool = True) -> Dict:
    """Render the actors (:class:`~mocap_core.data.multi_person.Actor`) for ``frames`` frames
    seen by ``camera`` (:class:`~mocap_core.data.synth2d.VirtualCamera`, static) into
    ``out_dir`` (module docstring); deterministic from ``seed``. ``head_details``: heads with
    hair and a face (:func:`~mocap_core.render.clip.place_body`; the renders cached before
    session 42 have plain heads). Returns the meta dict."""
    import cv2
    from anny import KeypointsRegressor

    from ..data.multi_person import place
    from ..kinematics import forward_kinematics
    from .body import load_anny, sample_phenotype
    from .clip import place_body
    from .scene import SceneRenderer, sample_appearance, vertex_colours

    t0 = time.perf_counter()
    model = model if model is not None else load_anny()
    coco = KeypointsRegressor.coco(model)
    rng = np.random.default_rng(seed)
    W, H = camera.intrinsics.width, camera.intrinsics.height
    K = camera.intrinsics.K
    A = len(actors)
    kp_mesh = np.zeros((frames, A, NUM_KEYPOINTS, 3))
    present = np.zeros((frames, A), dtype=bool)
    depth = np.full((frames, A), np.inf)
    joints_cam = np.full((frames, A, 18, 3), np.nan)
    verts: List[Dict[int, np.ndarray]] = []
    colours, phenotypes, heights, regions0, faces0 = [], [], [], None, None
    appearances = [sample_appearance(rng) for _ in actors]
    for a, actor in enumerate(actors):
        rot, root = place(actor)
        sk = actor.motion.skeleton
        fk = forward_kinematics(sk.parents, sk.offsets, rot, root)
        pheno = sample_phenotype(rng, model)
        placed = place_body(model, coco, sk, fk.global_rotations, fk.positions[:, 0],
                            np.asarray(actor.motion.contacts, dtype=bool), pheno,
                            about=np.asarray(actor.anchor, dtype=np.float64),
                            head_details=head_details)
        phenotypes.append(pheno)
        heights.append(float(placed.body.height()))
        if regions0 is None:
            regions0, faces0 = placed.regions, placed.body.faces
        colours.append(vertex_colours(appearances[a], placed.regions))
        by_frame: Dict[int, np.ndarray] = {}
        stop = frames if actor.stop is None else min(actor.stop, frames)
        for f in range(actor.start, stop):
            k = actor.clip_start + f - actor.start
            if k >= len(placed.vertices):
                break
            by_frame[f] = placed.vertices[k]
            present[f, a] = True
            pc = camera.world_to_camera(placed.keypoints_world[k])
            uv = project_pinhole(K, pc)
            inside = (uv[:, 2] > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < W) & (uv[:, 1] >= 0) & \
                (uv[:, 1] < H) & placed.have
            kp_mesh[f, a, :, :2] = uv[:, :2]
            kp_mesh[f, a, :, 2] = inside
            depth[f, a] = float(np.linalg.norm(camera.world_to_camera(placed.pelvis[k])))
            joints_cam[f, a] = camera.world_to_camera(placed.joints[k])
        verts.append(by_frame)
    out_dir = Path(out_dir)
    tmp = out_dir.with_name(out_dir.name + '.partial')
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    centre = np.mean([np.asarray(a.anchor, dtype=np.float64) for a in actors], axis=0)
    renderer = SceneRenderer(W, H, K, faces0, regions0, appearances[0], centre=centre)
    fps = float(actors[0].motion.fps)
    writer = cv2.VideoWriter(str(tmp / 'video.mp4'), cv2.VideoWriter_fourcc(*'mp4v'), fps,
                             (W, H))
    try:
        for f in range(frames):
            bodies = [(verts[a][f], colours[a]) for a in range(A) if f in verts[a]]
            writer.write(renderer.render_bodies(bodies, camera.rotation, camera.position))
            if progress is not None:
                progress(1)
    finally:
        writer.release()
        renderer.close()
    np.savez_compressed(tmp / 'data.npz', keypoints_mesh=kp_mesh, present=present, depth=depth,
                        joints_camera=joints_cam, heights_m=np.array(heights), K=K,
                        image_size=np.array([W, H]), fps=np.array(fps))
    meta = {'format': PEOPLE_FORMAT, 'scene': scene, 'seed': seed, 'frames': frames,
            'fps': fps, 'actors': A, 'phenotypes': phenotypes, 'heights_m': heights,
            'appearances': [ap.to_dict() for ap in appearances], 'head_details': head_details,
            'seconds': time.perf_counter() - t0}
    (tmp / 'meta.json').write_text(json.dumps(meta, indent=1))
    (tmp / 'done').write_text(str(PEOPLE_FORMAT))
    shutil.rmtree(out_dir, ignore_errors=True)
    os.replace(tmp, out_dir)
    return meta


def is_done(out_dir: Path) -> bool:
    """Whether ``out_dir`` holds a complete clip of the current format."""
    done = Path(out_dir) / 'done'
    return done.exists() and done.read_text().strip() == str(PEOPLE_FORMAT)


def match_rows(rows: np.ndarray, truth_kp: np.ndarray, min_confidence: float = 0.3
               ) -> np.ndarray:
    """Which actor each detected row is: (R, 23, 3) detected keypoints and (A, 23, 3) the
    actors' projected mesh keypoints of the same frame (confidence 0 = not in the image or
    absent). The cost of (row, actor) is the median distance over the keypoints seen in both,
    relative to the actor's height in the image; rows and actors are paired one to one at
    the least total cost (Hungarian), and a pair costlier than :data:`MATCH_FRACTION` is no
    match. Returns (R,) actor indices, -1 for a row that is nobody."""
    from scipy.optimize import linear_sum_assignment

    rows = np.asarray(rows, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
    truth_kp = np.asarray(truth_kp, dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
    out = np.full(len(rows), -1, dtype=int)
    if not len(rows) or not len(truth_kp):
        return out
    cost = np.full((len(rows), len(truth_kp)), np.inf)
    for a, t in enumerate(truth_kp):
        seen_t = t[:, 2] > 0
        if seen_t.sum() < 4:
            continue
        height = max(float(np.ptp(t[seen_t, 1])), 1.0)
        for r, d in enumerate(rows):
            both = seen_t & (d[:, 2] > min_confidence)
            if both.sum() >= 4:
                cost[r, a] = np.median(np.linalg.norm(d[both, :2] - t[both, :2], axis=1)) / height
    finite = np.where(np.isfinite(cost), cost, 1e6)
    r_idx, a_idx = linear_sum_assignment(finite)
    for r, a in zip(r_idx, a_idx):
        if cost[r, a] <= MATCH_FRACTION:
            out[r] = a
    return out


def score_people_clip(clip_dir: Path, keypoints: Sequence[np.ndarray],
                      ids: Sequence[np.ndarray], min_inside: int = 12) -> Dict:
    """Score a keypoint stream against a rendered clip.

    Args:
        clip_dir: a folder of :func:`render_people`.
        keypoints: per frame, the (R, 23, 3) rows of the keypoint cloud.
        ids: per frame, the (R,) ids of the rows (0 = nobody: not published as a person).
        min_inside: an actor counts as in the picture in a frame when at least this many of
            their mesh keypoints are inside the image (``recall`` is over those frames).

    Returns :func:`~mocap_core.data.multi_person.identity_metrics` plus ``recall`` (actor
    frames in the picture with a detected row of theirs that has an id), ``recall_unhidden``
    (the same over frames where the actor is not the farther of two overlapping people),
    ``frames``, ``median_error_rel_height`` (a matched row's median keypoint distance over
    the actor's height in the image), ``find_delays`` (:func:`find_delays` over the frames
    where the actor is in the picture and not hidden) and the per-actor ``ids``.
    """
    from ..data.multi_person import identity_metrics

    data = np.load(Path(clip_dir) / 'data.npz')
    truth_kp, depth = data['keypoints_mesh'], data['depth']
    F = min(len(truth_kp), len(keypoints))
    truths, published, errors = [], [], []
    in_picture = (truth_kp[..., 2] > 0).sum(axis=2) >= min_inside           # (F, A)
    hidden = _hidden(truth_kp, depth)
    found = np.zeros_like(in_picture)
    ids_of: Dict[int, set] = {}
    for f in range(F):
        rows = np.asarray(keypoints[f], dtype=np.float64).reshape(-1, NUM_KEYPOINTS, 3)
        rid = np.asarray(ids[f]).reshape(-1)
        real = rid > 0
        rows, rid = rows[real], rid[real]
        truth = match_rows(rows, truth_kp[f])
        truths.append(truth)
        published.append({r: int(i) for r, i in enumerate(rid)})
        for r, a in enumerate(truth):
            if a >= 0:
                found[f, a] = True
                ids_of.setdefault(int(a), set()).add(int(rid[r]))
                t = truth_kp[f, a]
                both = (t[:, 2] > 0) & (rows[r, :, 2] > 0.3)
                height = max(float(np.ptp(t[t[:, 2] > 0, 1])), 1.0)
                errors.append(float(np.median(np.linalg.norm(
                    rows[r, both, :2] - t[both, :2], axis=1)) / height))
    m = identity_metrics(truths, published)
    pic = in_picture[:F]
    unhidden = pic & ~hidden[:F]
    m.update(frames=F, recall=float(found[:F][pic].mean()) if pic.any() else float('nan'),
             find_delays=find_delays(found[:F], unhidden),
             recall_unhidden=float(found[:F][unhidden].mean()) if unhidden.any()
             else float('nan'),
             median_error_rel_height=float(np.median(errors)) if errors else float('nan'),
             ids={str(a): sorted(v) for a, v in sorted(ids_of.items())})
    return m


def find_delays(found: np.ndarray, visible: np.ndarray, min_run: int = MIN_APPEARANCE_FRAMES
                ) -> List[Tuple[int, bool]]:
    """How long each appearance of each actor waited for an id.

    Args:
        found: (F, A) bool, the actor has a published row with an id in the frame.
        visible: (F, A) bool, the actor is in the picture and not hidden behind a nearer one.
        min_run: appearances (runs of ``visible`` frames) shorter than this are left out.
    Returns: per appearance, in actor and frame order, ``(frames, found)``: the frames from
    its first until the first with an id (0: found at once, e.g. followed through the
    occlusion before it), or its length and False when it never got one (also one that the
    clip's end cut short).
    """
    out: List[Tuple[int, bool]] = []
    F, A = visible.shape
    for a in range(A):
        v = np.concatenate([[False], visible[:, a], [False]]).astype(np.int8)
        starts = np.flatnonzero(np.diff(v) == 1)
        ends = np.flatnonzero(np.diff(v) == -1)
        for s, e in zip(starts, ends):
            if e - s < min_run:
                continue
            hit = np.flatnonzero(found[s:e, a])
            out.append((int(hit[0]), True) if len(hit) else (int(e - s), False))
    return out


def _hidden(truth_kp: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """(F, A) whether an actor's image box overlaps a nearer actor's box by more than a
    third of its own area (the farther of two overlapping people)."""
    F, A = truth_kp.shape[:2]
    out = np.zeros((F, A), dtype=bool)
    for f in range(F):
        boxes = []
        for a in range(A):
            seen = truth_kp[f, a, :, 2] > 0
            boxes.append(None if seen.sum() < 2 else (
                *truth_kp[f, a, seen, :2].min(axis=0), *truth_kp[f, a, seen, :2].max(axis=0)))
        for a in range(A):
            if boxes[a] is None:
                continue
            x0, y0, x1, y1 = boxes[a]
            area = max((x1 - x0) * (y1 - y0), 1.0)
            for b in range(A):
                if b == a or boxes[b] is None or not depth[f, b] < depth[f, a]:
                    continue
                u0, v0, u1, v1 = boxes[b]
                inter = max(0.0, min(x1, u1) - max(x0, u0)) * max(0.0, min(y1, v1) - max(y0, v0))
                if inter > area / 3:
                    out[f, a] = True
    return out
