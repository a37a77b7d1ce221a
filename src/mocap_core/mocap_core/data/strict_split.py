"""The stricter generalization split: whole subjects *and* whole motion families held out.

The committed split (``splits.py``) holds out CMU subjects and Bandai Namco content x style
combinations; every content and every style on its own is still seen in training. The strict
split keeps all of that validation and moves whole *families* from training to validation as
well, so that a model is judged on kinds of motion it has never seen:

========================  ===================================================================
family                    groups (``splits.clip_labels`` group names)
========================  ===================================================================
``dance``                 ``bandai/dataset-1/dance-short/*``, ``cmu/salsa``, ``cmu/indian``
``martial arts``          ``bandai/dataset-1/{kick,punch,slash}/*``
``style: old``            ``bandai/dataset-1/*/old`` (one Bandai Namco style, every content)
``style: exhausted``      ``bandai/dataset-2/*/exhausted`` (one style of the second dataset)
``validation``            the committed validation split (held-out subjects and combinations)
========================  ===================================================================

So ``strict train`` is a subset of the committed training split: a model trained on it can be
scored on both validations. Which weights ship is decided on this split's validation (with
projected and detector-placed keypoints) and on the rendered benchmark, not on the committed
validation alone.
"""

from __future__ import annotations

import fnmatch
from typing import Dict, List, Optional, Sequence, Tuple

from .splits import clip_labels

#: family -> group patterns (fnmatch) moved from training to validation.
HELD_OUT_FAMILIES: Dict[str, Tuple[str, ...]] = {
    'dance': ('bandai/dataset-1/dance-short/*', 'cmu/salsa', 'cmu/indian'),
    'martial arts': ('bandai/dataset-1/kick/*', 'bandai/dataset-1/punch/*',
                     'bandai/dataset-1/slash/*'),
    'style: old': ('bandai/dataset-1/*/old',),
    'style: exhausted': ('bandai/dataset-2/*/exhausted',),
}

STRICT_SPLITS = ('strict_train', 'strict_validation')


def family_of(clip_id: str) -> Optional[str]:
    """The held-out family of a clip, or None (it stays where the committed split puts it)."""
    group = clip_labels(clip_id)['group']
    for family, patterns in HELD_OUT_FAMILIES.items():
        if any(fnmatch.fnmatchcase(group, p) for p in patterns):
            return family
    return None


def strict_assignment(clip_ids: Sequence[str], committed: Sequence[str]) -> List[Tuple[str, str]]:
    """Per clip ``(strict split, family)``: ``committed`` is each clip's committed split
    (``'train'`` / ``'validation'``); the family is ``'validation'`` for committed validation
    clips, the held-out family, or ``''`` for strict training clips."""
    out = []
    for cid, split in zip(clip_ids, committed):
        if split == 'validation':
            out.append(('strict_validation', 'validation'))
            continue
        fam = family_of(cid)
        out.append(('strict_validation', fam) if fam else ('strict_train', ''))
    return out


def load_strict(split: str, dataset=None):
    """``(motions, families)`` of ``'strict_train'`` or ``'strict_validation'`` from the
    dataset cache (``dataset.load_split``)."""
    from .dataset import load_split
    if split not in STRICT_SPLITS:
        raise ValueError(f'unknown strict split {split!r}; use {" or ".join(STRICT_SPLITS)}')
    motions, families = [], []
    for committed in ('train', 'validation'):
        ds = load_split(committed, dataset)
        ids = [str(i) for i in ds.ids]
        for i, (s, fam) in enumerate(strict_assignment(ids, [committed] * len(ids))):
            if s == split:
                motions.append(ds.motion(i))
                families.append(fam)
    return motions, families
