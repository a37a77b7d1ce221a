"""Forces and torques of the physics cycle on walking, against gait biomechanics (no ROS).

``mocap eval gait`` runs the cycle (default parameters, the true floor) on ground-truth
walking clips and reports what a gait laboratory would measure:

* the **vertical ground reaction force** of each foot over its gait cycle (heel strike to the
  next heel strike of the same foot, from the ground-truth contact labels), resampled to
  0..100 % and averaged over strides, in body weights; the mean over all frames of the total
  vertical force (1.0 for a body that neither rises nor sinks on average); the two peaks of
  the stance phase and the trough between them;
* the **peak joint moments** of ankle, knee and hip per kg of body mass: the sagittal
  component (about the joint frame's y axis: the skeleton's frames are x forward, y left,
  z up at rest, so y is the flexion axis of the leg joints) and the magnitude.

The segment masses of the model are fixed fractions of the body mass (de Leva), so forces in
body weights and moments per kg do not depend on the mass given: they are properties of the
motion. The default mass is still the one passed in (``--body-mass``; ground-truth clips
carry no mass).

Published normal-walking values to compare with (self-selected speed, adults): vertical GRF
with two peaks of about 1.1-1.3 body weights and a mid-stance trough of about 0.7-0.8, and a
peak ankle plantarflexion moment of about 1.5 N m/kg at push-off (Winter, D. A., *The
Biomechanics and Motor Control of Human Gait*, University of Waterloo Press, 1987). Knee and
hip peaks differ between laboratories: at push-off Winter reports about 0.16 (knee) and
0.4 N m/kg (hip flexor), other laboratories about 0.8 and 1.4 (the comparison with Kadaba et
al., *J. Orthop. Res.* 7 (1989), in the BIOMCH-L discussion "Winter's knee and hip
kinetics", 1996). ``docs/benchmarks/physics_gait.md`` holds the figures.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Dict, List, Sequence

import numpy as np

from mocap_core.gait import CYCLE_POINTS, heel_strikes, stride_curves

from ..cycle_params import PhysicsParams
from ..online import OnlinePhysics
from .evaluate import Clip

#: leg joints reported, per side
LEG_JOINTS = ('hip', 'knee', 'ankle')


@dataclass
class GaitRun:
    """The cycle's forces and torques on one clip (floor frame)."""

    name: str
    fps: float
    foot_force_z: np.ndarray        # (F, 2) vertical GRF of the left and right foot, N
    torques: Dict[str, np.ndarray]  # '<side>_<joint>' -> (F, 3) joint-frame torque, N m
    labels: np.ndarray              # (F, 4) bool ground-truth contacts
    body_mass: float
    residual: np.ndarray            # (F,) residual root force / weight


def run_gait(clip: Clip, params: PhysicsParams) -> GaitRun:
    """Run the cycle over ``clip`` on the true floor, clean input, frame by frame."""
    online = OnlinePhysics(replace(params), clip.to_world, report=lambda n: None,
                           skeleton=clip.skeleton)
    F = clip.num_frames
    fz = np.zeros((F, 2))
    names = clip.skeleton.joint_names
    keys = [f'{s}_{j}' for s in ('left', 'right') for j in LEG_JOINTS]
    tq = {k: np.zeros((F, 3)) for k in keys}
    resid = np.zeros(F)
    for i in range(F):
        t = float(clip.stamps[i])
        out = online.step(int(round(t * 1e9)), clip.pose(i), probabilities=clip.contacts[i],
                          time_s=t)
        if out is None:
            raise RuntimeError(f'{clip.name}: frame {i} dropped')
        r = out.result
        fz[i] = [r.feet['left'].force[2], r.feet['right'].force[2]]
        model = online.cycle.model
        for k in keys:
            j = names.index(k)
            iv = model.idx_v[j]
            tq[k][i] = r.torques[iv:iv + 3]
        resid[i] = r.residual_ratio
    return GaitRun(clip.name, clip.fps, fz, tq, np.asarray(clip.labels, dtype=bool),
                   params.body_mass, resid)


def _peaks(curve: np.ndarray) -> Dict[str, float]:
    """The loading peak (5-30 % of the cycle), the mid-stance trough (20-45 %) and the
    push-off peak (40-62 %) of a foot's stance curve (walking: stance is about 60 %)."""
    n = len(curve) - 1

    def window(a: float, b: float) -> np.ndarray:
        return np.arange(int(round(a * n)), int(round(b * n)) + 1)
    w1, wt, w2 = window(0.05, 0.30), window(0.20, 0.45), window(0.40, 0.62)
    i1 = int(w1[np.argmax(curve[w1])])
    i2 = int(w2[np.argmax(curve[w2])])
    return {'peak_1_bw': float(curve[i1]), 'peak_2_bw': float(curve[i2]),
            'trough_bw': float(curve[wt].min()), 'peak_1_at': i1 / n, 'peak_2_at': i2 / n}


def analyse(runs: Sequence[GaitRun]) -> dict:
    """GRF curves and moment peaks over the runs (module docstring)."""
    curves = []
    total = []
    moments: Dict[str, List[np.ndarray]] = {}
    weight = None
    for run in runs:
        weight = run.body_mass * 9.81
        total.append(run.foot_force_z.sum(axis=1) / weight)
        for side, (foot, heel) in enumerate((('left', 0), ('right', 2))):
            strikes = heel_strikes(run.labels[:, heel])
            c = stride_curves(run.foot_force_z[:, side] / weight, strikes)
            curves.append(c)
            for j in LEG_JOINTS:
                tau = run.torques[f'{foot}_{j}'] / run.body_mass
                for part, vals in (('sagittal', tau[:, 1]),
                                   ('magnitude', np.linalg.norm(tau, axis=1))):
                    sc = stride_curves(vals, strikes)
                    moments.setdefault(f'{j}_{part}', []).append(sc)
    grf = np.concatenate(curves) if curves else np.zeros((0, CYCLE_POINTS))
    out: dict = {
        'strides': int(len(grf)),
        'mean_total_vertical_grf_bw': float(np.mean(np.concatenate(total))) if total else
        float('nan'),
        'residual_root_over_weight_median': float(np.median(np.concatenate(
            [r.residual for r in runs]))),
    }
    if len(grf):
        mean_curve = grf.mean(axis=0)
        out['grf_curve_bw'] = mean_curve.tolist()
        out['grf_curve_std_bw'] = grf.std(axis=0).tolist()
        out.update(_peaks(mean_curve))
    out['moments_per_kg'] = {}
    for key, parts in moments.items():
        allc = np.concatenate(parts)
        if not len(allc):
            continue
        mean = allc.mean(axis=0)
        out['moments_per_kg'][key] = {
            'peak_abs': float(np.abs(mean).max()),
            'peak_positive': float(mean.max()), 'peak_negative': float(mean.min()),
            'curve': mean.tolist()}
    return out


def plot(result: dict, path) -> None:
    """Vertical GRF and sagittal leg moments over the gait cycle (PNG)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    x = np.linspace(0, 100, CYCLE_POINTS)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    if 'grf_curve_bw' in result:
        m = np.array(result['grf_curve_bw'])
        s = np.array(result['grf_curve_std_bw'])
        axes[0].plot(x, m, color='C0', label='physics (mean over strides)')
        axes[0].fill_between(x, m - s, m + s, color='C0', alpha=0.2, label='+- 1 std')
    axes[0].axhspan(1.1, 1.3, color='C2', alpha=0.15, label='published peaks, 1.1-1.3 BW')
    axes[0].axhline(1.0, color='k', lw=0.5)
    axes[0].set_xlabel('gait cycle (%), heel strike to heel strike')
    axes[0].set_ylabel('vertical GRF of the foot (body weights)')
    axes[0].legend(fontsize=8)
    for j, color in zip(LEG_JOINTS, ('C0', 'C1', 'C3')):
        entry = result['moments_per_kg'].get(f'{j}_sagittal')
        if entry:
            axes[1].plot(x, entry['curve'], color=color, label=j)
    axes[1].axhspan(-1.6, -1.3, color='C3', alpha=0.1)
    axes[1].axhspan(1.3, 1.6, color='C3', alpha=0.1,
                    label='published ankle peak, 1.3-1.6 N m/kg')
    axes[1].set_xlabel('gait cycle (%)')
    axes[1].set_ylabel('sagittal joint moment (N m/kg, joint frame y)')
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


__all__ = ['GaitRun', 'run_gait', 'heel_strikes', 'stride_curves', 'analyse', 'plot',
           'LEG_JOINTS', 'CYCLE_POINTS']
