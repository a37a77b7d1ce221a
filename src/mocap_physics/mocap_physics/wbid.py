"""Whole-body inverse dynamics of one physics sub-step, as one QP (no ROS imports).

The dynamically consistent mode of the physics cycle (``dynamics='whole_body'``, the default;
``docs/physics.md`` explains the choice and the measurements). Each sub-step finds the joint
accelerations ``qdd`` (nv,), the joint torques ``tau`` (nv - 6,), the contact forces
``lambda_c`` (3,) of the stance contact points (world axes, N) and a residual root wrench
``r`` (6,) such that the equation of motion of the floating base holds::

    M(q) qdd + h(q, qd) = S^T tau + J_c^T lambda + S_root^T r

where ``S = [0 | I]`` selects the actuated joints and ``S_root = [I | 0]`` the free-flyer.
The joint rows define ``tau``, so only the six root rows remain as equality constraints. The
variables are ``x = [qdd, lambda / (m g), r_w / (m g)]`` with ``r_w`` the residual force and
moment on world axes (Pinocchio's root velocity, hence ``r``, is in the root frame:
``r = blockdiag(R^T, R^T) r_w``). The cycle then runs Pinocchio's forward dynamics (``aba``)
on ``S^T tau + J^T lambda + S_root^T r``, so the forces are what moves the body.

Constraints (per sub-step):

* root rows of the equation of motion (6 equalities);
* stance contacts do not accelerate, the dynamic form of the foot stick::

      J_c qdd + Jdot_c qd = a_ref,c = -2 k v_c - k^2 (p_c - p_anchor,c)

  (``a_ref``, with ``k = stance_gain``, is a critically damped stabilisation that holds a
  point at its anchor on the floor, z = 0; heel and toe of one foot are one rigid body, so
  with both in stance the rows are the heel's x, y, z, the toe's z and the toe's horizontal
  acceleration across the heel-toe line: :func:`stance_rows`);
* every stance force inside the friction pyramid inscribed in the cone of coefficient ``mu``
  (``|lambda_x|, |lambda_y| <= mu / sqrt(2) lambda_z``, ``lambda_z >= 0``);
* the residual bounded on world axes: ``|r_w,i| <= residual_bound m g`` (force rows, N) and
  ``residual_moment_bound m g`` (moment rows, N m).

Objective (dimensionless, body-weight units)::

    sum_i w_i (qdd_i - a_des,i)^2 + w_h |r_w,xy / m g|^2 + w_r |r_w,z / m g|^2
    + w_r |m_w / m g|^2 + w_s |lambda - lambda_prev|^2 / (m g)^2 + w_f |lambda|^2 / (m g)^2

with ``w_i = max(M_ii / m, 1e-3)`` (the inertia-scaled metric of the cycle's PD, floored for
conditioning) and ``a_des`` the PD's desired acceleration (eq. 7 without the inertia factor).

Sliding: when the total force of a foot's stance points ends on the pyramid's edge (friction
saturated) and holding the feet needed a horizontal residual force of at least
``slide_threshold`` body weights, the QP is solved again with that foot's horizontal rows
released and the friction of each of its points fixed to the kinetic value
``mu / sqrt(2) lambda_z`` (inside the pyramid) against the sliding direction (the point's
horizontal velocity, or the direction of the force the foot needed). A foot therefore slides
when the motion asks for more friction than the floor can give, and sticks otherwise.

Losing balance: the residual is the only force that can hold a body whose target the feet do
not support. Its weights make it expensive and its bounds limit it; :class:`WbidResult` says
whether a bound was reached so that the cycle can count it.

Solution: by default (``condensed``) ``qdd`` is eliminated in closed form. For fixed
``y = [lambda / (m g), r_w / (m g)]`` the dynamics rows read ``E qdd = e - F y`` and the best
``qdd`` is ``a_des + W^-1 E^T mu`` with ``K mu = c - F y`` (``K = E W^-1 E^T``, ``c = e - E
a_des``, ``W = diag(w)``) at a cost of ``1/2 (F y - c)^T K^-1 (F y - c)``. What remains is a
dense QP over ``y`` alone (at most 18 variables), solved with DAQP (a dual active-set solver:
exact on its active set, deterministic, so ``mocap process`` stays bit-identical). It has the
same optimum as the QP over all variables, which is kept (``condensed=False``, or when ``K``
is not safely positive definite, or DAQP fails) and solved with OSQP (deterministic) or
ProxQP's dense solver (``solver='proxqp'``, which then also solves the condensed QP; its result
varies in the last bits from run to run). One OSQP or ProxQP solver is kept per problem
structure and warm-started.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

import osqp
import scipy.sparse as sp
from scipy.linalg import lapack

try:
    from proxsuite import proxqp
except ImportError:  # pragma: no cover - optional (solver='proxqp')
    proxqp = None
try:
    import daqp
except ImportError:  # pragma: no cover - the condensed QP then runs on OSQP
    daqp = None

from .qp import _OSQP_OK, PYRAMID_FACTOR, _status_name




#: QP solvers the whole-body QP can use.
SOLVERS = ('osqp', 'proxqp')


class WbidUnavailable(RuntimeError):
    """ProxQP (proxsuite) is not installed."""


@dataclass
class WbidResult:
    """Solution of one whole-body inverse-dynamics QP.

    qdd: (nv,) joint accelerations (root: linear and angular, root frame).
    tau: (nv - 6,) joint torques, N m (each ball joint's torque in its own frame).
    forces: (C, 3) contact forces, world (floor) axes, N (zero off stance).
    residual: (6,) root residual wrench r (force N, moment N m, root frame).
    stance: (C,) points held by the stance rows. sliding: (C,) stance points that slid.
    saturated: the residual reached its bound on some row.
    ok: the solver converged. status: solver status text. solve_time: s. solves: QPs solved.
    """

    qdd: np.ndarray
    tau: np.ndarray
    forces: np.ndarray
    residual: np.ndarray
    stance: np.ndarray
    sliding: np.ndarray
    saturated: bool = False
    ok: bool = True
    status: str = 'solved'
    solve_time: float = 0.0
    solves: int = 0


_EX, _EY, _EZ = np.eye(3)


def across_line(xy: np.ndarray, c: int, k: int) -> Optional[Tuple[float, float]]:
    """The horizontal unit normal (x, y) of the line from point ``c`` to point ``k`` of one
    foot (``xy``: (C, 2) m), or None when they are less than 1 mm apart horizontally."""
    lx, ly = float(xy[k, 0] - xy[c, 0]), float(xy[k, 1] - xy[c, 1])
    length = (lx * lx + ly * ly) ** 0.5
    if length < 1e-3:
        return None
    return -ly / length, lx / length


def stance_rows(feet: Sequence[str], stance: np.ndarray, xy: np.ndarray,
                free_tangent: np.ndarray) -> Tuple[list, list]:
    """The (point, direction) pairs of the stance acceleration rows.

    Args:
        feet: (C,) foot of each contact point ('left' / 'right'); points of one foot are one
            rigid body.
        stance: (C,) bool, points held. xy: (C, 2) their horizontal positions, m.
        free_tangent: (C,) bool, points whose horizontal rows are released (sliding).
    Returns:
        two lists of the same length: the contact index of each row and its world direction
        (3,) (unit x, y, z, or the horizontal normal of the heel-toe line).
    """
    ex, ey, ez = _EX, _EY, _EZ
    idx: list = []
    dirs: list = []
    held = np.flatnonzero(stance).tolist()
    done = set()
    for c in held:
        if c in done:
            continue
        done.add(c)
        idx.append(c)
        dirs.append(ez)
        mates = [k for k in held if k != c and feet[k] == feet[c] and k not in done]
        if not free_tangent[c]:
            idx += [c, c]
            dirs += [ex, ey]
        for k in mates:
            done.add(k)
            idx.append(k)
            dirs.append(ez)
            if free_tangent[k]:
                continue
            if free_tangent[c]:
                idx += [k, k]
                dirs += [ex, ey]
                continue
            n = across_line(xy, c, k)
            if n is None:
                continue
            idx.append(k)
            dirs.append(np.array([n[0], n[1], 0.0]))
    return idx, dirs


class _Rows:
    """The layout of :func:`stance_rows` for one stance and sliding set: the rows along a
    world axis (``unit_pos`` in the row order, their point ``unit_c`` and axis
    ``unit_axis``), the rows across a heel-toe line (``normal_pos``, the point ``normal_k``
    and the foot's first point ``normal_ref`` that the line starts from), the stance points
    ``act``, the sliding stance points ``n_slide`` and the solver key of the problem."""

    def __init__(self, feet: Sequence[str], stance: np.ndarray, sliding: np.ndarray) -> None:
        held = np.flatnonzero(stance)
        # the layout with the points of one foot apart (no degenerate heel-toe line)
        spread = np.zeros((len(stance), 2))
        spread[:, 0] = np.arange(len(stance))
        row_c, row_d = stance_rows(feet, stance, spread, sliding)
        unit = [(r, c, a) for r, (c, d) in enumerate(zip(row_c, row_d))
                for a, ax in enumerate((_EX, _EY, _EZ)) if d is ax]
        first = {}
        for c in held:
            first.setdefault(feet[c], int(c))
        normal = [(r, c, first[feet[c]]) for r, (c, d) in enumerate(zip(row_c, row_d))
                  if not any(d is ax for ax in (_EX, _EY, _EZ))]
        self.n_rows = len(row_c)
        self.unit_pos = np.array([u[0] for u in unit], dtype=int)
        self.unit_c = np.array([u[1] for u in unit], dtype=int)
        self.unit_axis = np.array([u[2] for u in unit], dtype=int)
        self.normal_pos = np.array([n[0] for n in normal], dtype=int)
        self.normal_k = np.array([n[1] for n in normal], dtype=int)
        self.normal_ref = np.array([n[2] for n in normal], dtype=int)
        self.act = held
        self.n_slide = int((sliding & stance).sum())
        self.key = (len(held), len(row_c), self.n_slide, tuple(row_c),
                    tuple(np.flatnonzero(sliding)))

    def normal_directions(self, xy: np.ndarray) -> Optional[np.ndarray]:
        """(n, 3) the across-the-line directions of the normal rows for the points' ``xy``
        (C, 2), as :func:`stance_rows` computes them; None when a heel and toe are closer
        than 1 mm horizontally (stance_rows then leaves that row out)."""
        out = np.zeros((len(self.normal_pos), 3))
        for i, (k, c) in enumerate(zip(self.normal_k, self.normal_ref)):
            n = across_line(xy, c, k)
            if n is None:
                return None
            out[i, :2] = n
        return out


class WholeBodyID:
    """The whole-body inverse-dynamics QP (module docstring), one instance per cycle.

    One solver is kept per problem structure (stance rows, sliding points) and warm-started
    from its previous solution.

    Args:
        nv: velocity dimension of the model. num_contacts: C.
        friction: Coulomb coefficient mu (the pyramid uses mu / sqrt(2)).
        residual_weight: w_r of the vertical force and the moment rows.
        residual_horizontal_weight: w_r of the horizontal force rows (world axes).
        residual_bound: force bound, body weights.
        residual_moment_bound: moment bound, body weight metres.
        smoothness: w_s. force_regularization: w_f (> 0: the least internal force).
        slide_threshold: body weights; a foot whose friction is saturated slides only when
            the feet-fixed solution needed a residual root force at least this large,
            averaged over ``slide_time`` (s; 0: at once) while the foot was saturated.
        eps: solver tolerance (dimensionless units).
        solver: 'osqp' (default: deterministic, bit-identical runs) or 'proxqp' (ProxQP's
            dense solver: faster, but its result varies in the last bits from run to run;
            the comparison is in ``docs/physics.md``).
        condensed: solve the QP over the forces and the residual alone, ``qdd`` eliminated
            in closed form (default; the same optimum, about 2x faster); False: the QP over
            all variables (kept for comparison, and used when the dynamics rows are
            dependent).
    """

    def __init__(self, nv: int, num_contacts: int = 4, friction: float = 0.8,
                 residual_weight: float = 300.0, residual_horizontal_weight: float = 3000.0,
                 residual_bound: float = 1.0,
                 residual_moment_bound: float = 0.5, smoothness: float = 1e-2,
                 force_regularization: float = 1e-4, slide_threshold: float = 0.05,
                 slide_time: float = 0.0, eps: float = 1e-7, max_iter: int = 1000,
                 solver: str = 'osqp', condensed: bool = True) -> None:
        if solver not in SOLVERS:
            raise ValueError(f'solver must be one of {SOLVERS}, got {solver!r}')
        if solver == 'proxqp' and proxqp is None:
            raise WbidUnavailable('solver proxqp needs proxsuite (pip install proxsuite)')
        self.solver = solver
        self.condensed = bool(condensed)
        #: OSQP's tolerance (an ADMM solver: polishing gives the accuracy of an active set)
        self.osqp_eps = 1e-5
        if not friction > 0 or residual_weight <= 0 or force_regularization <= 0:
            raise ValueError('friction, residual_weight and force_regularization must be > 0')
        if residual_bound < 0 or residual_moment_bound < 0 or smoothness < 0:
            raise ValueError('residual bounds and smoothness must be >= 0')
        self.nv = int(nv)
        self.num_contacts = int(num_contacts)
        self.friction = float(friction)
        self.mu_pyramid = self.friction * PYRAMID_FACTOR
        self.residual_weight = float(residual_weight)
        self.residual_horizontal_weight = float(residual_horizontal_weight)
        self.residual_bound = float(residual_bound)
        self.residual_moment_bound = float(residual_moment_bound)
        self.smoothness = float(smoothness)
        self.force_regularization = float(force_regularization)
        self.slide_threshold = float(slide_threshold)
        self.slide_time = float(slide_time)
        self._need: dict = {}
        self.eps = float(eps)
        self.max_iter = int(max_iter)
        self._prev = np.zeros((self.num_contacts, 3))
        self._solvers: dict = {}
        self._rows_cache: dict = {}
        #: the last solver's status text
        self.last_status = ''
        self._feet_key: Optional[tuple] = None
        self._by_foot: dict = {}
        self._structures: dict = {}

    def reset(self) -> None:
        """Forget the previous forces (smoothness term) and the warm starts."""
        self._prev[:] = 0.0
        self._need.clear()
        self._solvers.clear()

    # ------------------------------------------------------------------------------------
    def solve(self, M: np.ndarray, h: np.ndarray, a_des: np.ndarray, Jc: np.ndarray,
              drift: np.ndarray, stance: np.ndarray, a_ref: np.ndarray, xy: np.ndarray,
              velocity: np.ndarray, feet: Sequence[str], body_mass: float,
              gravity: float = 9.81, root_rotation: Optional[np.ndarray] = None,
              dt: float = 0.0, weight_scale: Optional[np.ndarray] = None) -> WbidResult:
        """Solve one sub-step.

        Args:
            M: (nv, nv) joint-space inertia (full, symmetric). h: (nv,) nonlinear effects.
            a_des: (nv,) desired accelerations (PD). Jc: (C, 3, nv) contact Jacobians
                (linear, world-aligned axes). drift: (C, 3) ``Jdot_c qd``, m/s^2.
            stance: (C,) bool, points in stance (they carry forces and do not accelerate).
            a_ref: (C, 3) stabilising reference acceleration of each stance point, m/s^2.
            xy: (C, 2) horizontal positions, m. velocity: (C, 3) point velocities, m/s.
            feet: (C,) foot of each point. body_mass: kg. gravity: m/s^2.
            root_rotation: (3, 3) root orientation (root frame -> world); the residual's
                weights and bounds apply on world axes (identity when None).
            dt: the sub-step, s: the time base of ``slide_time`` (0: no averaging).
            weight_scale: (nv,) factors on the tracking weights ``w_i`` (None: all 1), e.g.
                larger on the limbs that carry no stance point, whose deviation from the
                PD then costs more than the stance legs' and the root's.
        """
        R = np.eye(3) if root_rotation is None else np.asarray(root_rotation, dtype=float)
        t0 = time.perf_counter()
        stance = np.asarray(stance, dtype=bool)
        sliding = np.zeros(self.num_contacts, dtype=bool)
        slide_dir = np.zeros((self.num_contacts, 2))
        any_stance = bool(stance.any())
        if not any_stance:
            self._need.clear()                     # flight: no foot carries a history
        res = self._solve(M, h, a_des, Jc, drift, stance, a_ref, xy, sliding, slide_dir,
                          feet, body_mass, gravity, R, weight_scale)
        solves = 1
        if res is not None and any_stance:
            lam, r1 = res[1], res[2]
            # a foot slides when its total friction is saturated: one point of a rigid foot
            # at its own pyramid's edge is held by the other one
            sat = np.zeros(self.num_contacts, dtype=bool)
            by_foot = self._foot_points(feet)
            for pts in by_foot.values():
                pts = pts[stance[pts]]
                if len(pts) == 0:
                    continue
                f = lam[pts].sum(axis=0)
                if f[2] > 1e-6 and max(abs(f[0]), abs(f[1])) >= \
                        self.mu_pyramid * f[2] * (1 - 1e-3):
                    sat[pts] = True
            # ... and holding it needed the residual: the feet-fixed solution leaned on a
            # root force the floor could not give (a body that can follow its target with
            # the friction it has keeps its feet where they are)
            # (averaged over slide_time: a lifter's noise asks for a burst of force that no
            # foot could give, a real pull lasts)
            need = float(np.linalg.norm((R @ r1[:3])[:2])) / (body_mass * gravity)
            a = 1.0 if self.slide_time <= 0.0 or dt <= 0.0 else dt / (self.slide_time + dt)
            for foot, pts in by_foot.items():
                if not stance[pts].any():          # a foot in the air starts afresh
                    self._need.pop(foot, None)
                    continue
                old = self._need.get(foot, 0.0)
                self._need[foot] = old + a * ((need if sat[pts].any() else 0.0) - old)
                if self._need[foot] < self.slide_threshold:
                    sat[pts] = False
            if sat.any():
                for c in np.flatnonzero(sat):
                    v = velocity[c, :2]
                    speed = float(np.linalg.norm(v))
                    if speed > 1e-2:
                        slide_dir[c] = -v / speed       # friction opposes the sliding
                    else:
                        f = lam[[k for k in range(self.num_contacts)
                                 if feet[k] == feet[c] and stance[k]], :2].sum(axis=0)
                        slide_dir[c] = f / max(float(np.linalg.norm(f)), 1e-12)
                sliding = sat
                res2 = self._solve(M, h, a_des, Jc, drift, stance, a_ref, xy, sliding,
                                   slide_dir, feet, body_mass, gravity, R, weight_scale)
                solves += 1
                if res2 is not None:
                    res = res2
                else:
                    sliding = np.zeros(self.num_contacts, dtype=bool)
        elapsed = time.perf_counter() - t0
        n_c = self.num_contacts
        if res is None:
            return WbidResult(np.zeros(self.nv), np.zeros(self.nv - 6), np.zeros((n_c, 3)),
                              np.zeros(6), stance, sliding, ok=False, status='failed',
                              solve_time=elapsed, solves=solves)
        qdd, lam, r, status = res
        weight = body_mass * gravity
        reach = np.abs(r)
        saturated = bool((self.residual_bound > 0 and
                          reach[:3].max() >= weight * self.residual_bound * (1 - 1e-3))
                         or (self.residual_moment_bound > 0 and
                             reach[3:].max() >= weight * self.residual_moment_bound * (1 - 1e-3)))
        tau = M[6:] @ qdd + h[6:] - np.einsum('cin,ci->n', Jc[:, :, 6:], lam)
        self._prev = lam.copy()
        return WbidResult(qdd, tau, lam, r, stance, sliding, saturated, True, status,
                          elapsed, solves)

    def _structure(self, feet: Sequence[str], stance: np.ndarray,
                   sliding: np.ndarray) -> '_Rows':
        """The stance rows' layout for this stance and sliding set (:class:`_Rows`), kept
        per set: which point and world axis each row of :func:`stance_rows` reads, and which
        rows are across a heel-toe line (their direction is the only part that changes from
        one sub-step to the next)."""
        cache_key = (tuple(feet), stance.tobytes(), sliding.tobytes())
        st = self._structures.get(cache_key)
        if st is None:
            st = _Rows(feet, stance, sliding)
            if len(self._structures) >= 64:
                self._structures.clear()
            self._structures[cache_key] = st
        return st

    def _foot_points(self, feet: Sequence[str]) -> dict:
        """{foot: (n,) int indices of its contact points}, cached per ``feet``."""
        key = tuple(feet)
        if self._feet_key != key:
            self._feet_key = key
            self._by_foot = {f: np.array([c for c, g in enumerate(key) if g == f], dtype=int)
                             for f in sorted(set(key))}
        return self._by_foot

    # ------------------------------------------------------------------------------------
    def _solve(self, M, h, a_des, Jc, drift, stance, a_ref, xy, sliding, slide_dir, feet,
               body_mass, gravity, R, weight_scale=None):
        """Build and solve the QP; returns (qdd, lambda N, r, status) or None on failure.

        The problem is built in two parts: the dynamics rows ``E qdd + F y = e`` (the six
        root rows of the equation of motion, then the stance rows; ``y = [lambda / (m g),
        r_w / (m g)]``) and what concerns ``y`` alone (its diagonal weights, the kinetic
        friction equalities of sliding points, the pyramid and the residual bounds).
        """
        nv = self.nv
        C = self.num_contacts
        mg = body_mass * gravity
        st = self._structure(feet, stance, sliding)
        act, k, n_slide, key = st.act, len(st.act), st.n_slide, st.key
        ny = 3 * k + 6
        normals = st.normal_directions(xy)
        if normals is None:             # heel and toe over one another: as stance_rows says
            row_c, row_d = stance_rows(feet, stance, xy, sliding)
        n_dyn = 6 + st.n_rows if normals is not None else 6 + len(row_c)
        # -- the weights of qdd and of y -------------------------------------------------
        # (floored: the lightest DoFs, e.g. the toes, would make the problem ill-conditioned)
        w = np.maximum(np.diag(M) / body_mass, 1e-3)
        if weight_scale is not None:
            w = w * weight_scale
        hy = np.empty(ny)
        hy[:3 * k] = self.smoothness + self.force_regularization
        hy[3 * k:] = self.residual_weight
        hy[3 * k:3 * k + 2] = self.residual_horizontal_weight
        gy = np.zeros(ny)
        gy[:3 * k] = -self.smoothness * (self._prev[act] / mg).reshape(-1)
        # -- dynamics rows ---------------------------------------------------------------
        E = np.empty((n_dyn, nv))
        F = np.zeros((n_dyn, ny))
        e = np.empty(n_dyn)
        E[:6] = M[:6] / body_mass
        F[:6, :3 * k] = -gravity * Jc[act, :, :6].transpose(2, 0, 1).reshape(6, 3 * k)
        # r in world axes; the free-flyer's generalised force is in the root frame
        F[:3, 3 * k:3 * k + 3] = -gravity * R.T
        F[3:6, 3 * k + 3:] = -gravity * R.T
        e[:6] = -h[:6] / body_mass
        if normals is not None:
            # a row along a world axis is that axis' row of the point's Jacobian (the
            # product with a unit vector, exactly)
            rhs = a_ref - drift
            E[6 + st.unit_pos] = Jc[st.unit_c, st.unit_axis]
            e[6 + st.unit_pos] = rhs[st.unit_c, st.unit_axis]
            if len(normals):
                E[6 + st.normal_pos] = np.einsum('ri,rin->rn', normals, Jc[st.normal_k])
                e[6 + st.normal_pos] = np.einsum('ri,ri->r', normals, rhs[st.normal_k])
        elif row_c:
            d = np.asarray(row_d)
            E[6:] = np.einsum('ri,rin->rn', d, Jc[row_c])
            e[6:] = np.einsum('ri,ri->r', d, a_ref[row_c] - drift[row_c])
            key = (k, len(row_c), n_slide, tuple(row_c), tuple(np.flatnonzero(sliding)))
        # -- rows on y alone: kinetic friction (equalities), pyramid and bounds ------------
        A_y, S_y, lo, up = self._y_rows(act, sliding, slide_dir)
        x = None
        if self.condensed and daqp is not None:
            x, status = self._solve_condensed(key, w, a_des, E, F, e, hy, gy, A_y, lo, up,
                                              2 * n_slide)
        if x is None:      # the full QP: asked for, or dependent rows, or a failure
            x, status = self._solve_full(key, w, a_des, E, F, e, hy, gy, A_y, S_y, lo, up,
                                         n_slide)
        if x is None:
            return None
        qdd = x[:nv].copy()
        lam = np.zeros((C, 3))
        lam[act] = x[nv:nv + 3 * k].reshape(k, 3) * mg
        # solver tolerance must not put a force outside the pyramid (or, sliding, the cone)
        lam[:, 2] = np.maximum(lam[:, 2], 0.0)
        bound = (self.mu_pyramid * lam[:, 2])[:, None]
        lam[:, :2] = np.minimum(np.maximum(lam[:, :2], -bound), bound)
        r_world = x[nv + 3 * k:] * mg
        r = np.concatenate([R.T @ r_world[:3], R.T @ r_world[3:]])   # root frame
        return qdd, lam, r, status

    def _y_rows(self, act, sliding, slide_dir):
        """The rows on y alone: (A (m, ny), S (m, ny) bool, lower (m,), upper (m,)).

        First the kinetic friction equalities of the sliding points (2 each), then per stance
        point lambda_z >= 0 and, not sliding, the four pyramid faces, then the residual
        bounds. S holds the structural non-zeros, so that a solver's sparsity pattern keeps
        them. Cached per stance set when nothing slides (the rows are then constant).
        """
        k = len(act)
        if not sliding.any():
            rows = self._rows_cache.get((k, ()))
            if rows is not None:
                return rows
        slide_pts = [i for i, c in enumerate(act) if sliding[c]]
        cache_key = (k, tuple(slide_pts))
        n_slide = len(slide_pts)
        ny = 3 * k + 6
        m = 2 * n_slide + 5 * (k - n_slide) + n_slide + 6
        A = np.zeros((m, ny))
        S = np.zeros((m, ny), dtype=bool)
        lo = np.empty(m)
        up = np.empty(m)
        row = 0
        mu = self.mu_pyramid
        for i in slide_pts:
            # kinetic friction: lambda_t = mu' lambda_z * direction (inside the pyramid)
            for axis in (0, 1):
                A[row, 3 * i + axis] = 1.0
                A[row, 3 * i + 2] = -mu * slide_dir[act[i], axis]
                S[row, [3 * i + axis, 3 * i + 2]] = True
                lo[row] = up[row] = 0.0
                row += 1
        for i in range(k):
            j = 3 * i
            A[row, j + 2] = 1.0
            S[row, j + 2] = True
            lo[row], up[row] = 0.0, np.inf
            row += 1
            if i in slide_pts:
                continue
            for axis in (0, 1):
                for sign in (1.0, -1.0):
                    A[row, j + axis] = sign
                    A[row, j + 2] = -mu
                    S[row, [j + axis, j + 2]] = True
                    lo[row], up[row] = -np.inf, 0.0
                    row += 1
        for i in range(6):
            A[row, 3 * k + i] = 1.0
            S[row, 3 * k + i] = True
            bound = self.residual_bound if i < 3 else self.residual_moment_bound
            lo[row], up[row] = -bound, bound
            row += 1
        if not slide_pts:
            # shared by every later call: the callers and the solvers only read them (DAQP
            # needs writeable buffers, so they are not flagged read-only)
            self._rows_cache[cache_key] = (A, S, lo, up)
        return A, S, lo, up

    def _solve_condensed(self, key, w, a_des, E, F, e, hy, gy, A_y, lo, up, n_eq):
        """The QP over ``y`` alone: qdd eliminated in closed form (module docstring).

        For a given ``y`` the best ``qdd`` under ``E qdd = e - F y`` is
        ``a_des + W^-1 E^T mu`` with ``K mu = c - F y``, ``K = E W^-1 E^T``,
        ``c = e - E a_des``, and its cost ``1/2 (F y - c)^T K^-1 (F y - c)``. Returns
        (x = [qdd, y], status) or (None, 'singular') when K is not safely positive definite
        (dependent dynamics rows: the full QP is solved instead), (None, 'failed').
        """
        winv = 1.0 / w
        K = (E * winv) @ E.T
        c = e - E @ a_des
        # (LAPACK directly: numpy's and scipy's checked wrappers cost more than the solve)
        L, info = lapack.dpotrf(K, lower=1, clean=0)
        piv = np.abs(L.diagonal())
        if info != 0 or not np.isfinite(piv).all() or piv.min() ** 2 < 1e-10 * piv.max() ** 2:
            return None, 'singular'
        sol, info = lapack.dpotrs(L, np.column_stack([F, c]), lower=1)
        if info != 0:
            return None, 'singular'
        KF, Kc = sol[:, :-1], sol[:, -1]
        P = F.T @ KF
        P = 0.5 * (P + P.T)
        P.flat[::P.shape[0] + 1] += hy
        q = gy - F.T @ Kc
        if self.solver == 'osqp':     # the deterministic choice: DAQP on the small problem
            y = self._run_daqp(P, q, A_y, lo, up, n_eq)
        else:
            y, _ = self._run_proxqp(('condensed',) + key, P, q, A_y[:n_eq], lo[:n_eq],
                                    A_y[n_eq:], np.maximum(lo[n_eq:], -1e20),
                                    np.minimum(up[n_eq:], 1e20))
        if y is None:
            return None, 'failed'
        qdd = a_des + winv * (E.T @ (Kc - KF @ y))
        return np.concatenate([qdd, y]), 'solved'

    def _solve_full(self, key, w, a_des, E, F, e, hy, gy, A_y, S_y, lo, up, n_slide):
        """The QP over ``x = [qdd, y]`` (returns (x, status) or (None, 'failed'))."""
        nv, ny = E.shape[1], F.shape[1]
        n = nv + ny
        H = np.concatenate([w, hy])
        g = np.concatenate([-w * a_des, gy])
        n_dyn = E.shape[0]
        A = np.zeros((n_dyn + A_y.shape[0], n))
        A[:n_dyn, :nv] = E
        A[:n_dyn, nv:] = F
        A[n_dyn:, nv:] = A_y
        S = np.zeros(A.shape, dtype=bool)
        S[:n_dyn, :nv] = True                   # equation-of-motion and stance rows
        S[:6, nv:] = True                       # root rows: forces and residual
        S[n_dyn:, nv:] = S_y
        lower = np.concatenate([e, lo])
        upper = np.concatenate([e, up])
        if self.solver == 'osqp':
            x = self._run_osqp(('full',) + key, H, g, A, S, lower, upper)
            return x, ('solved' if x is not None else 'failed')
        n_eq = n_dyn + 2 * n_slide
        return self._run_proxqp(key, np.diag(H), g, A[:n_eq], lower[:n_eq], A[n_eq:],
                                np.where(np.isinf(lower[n_eq:]), -1e20, lower[n_eq:]),
                                np.where(np.isinf(upper[n_eq:]), 1e20, upper[n_eq:]))

    def _run_daqp(self, P, q, A, lower, upper, n_eq):
        """DAQP (a dual active-set solver: exact on its active set, deterministic) on the
        small dense condensed problem; the first ``n_eq`` rows are equalities."""
        sense = np.zeros(len(lower), dtype=np.int32)
        sense[:n_eq] = 5
        try:
            x, _, flag, _ = daqp.solve(P, q, A, np.minimum(upper, 1e30),
                                       np.maximum(lower, -1e30), sense)
        except Exception as exc:  # noqa: BLE001 - a solver error: the full QP is solved
            self.last_status = f'daqp error: {exc}'
            return None
        self.last_status = f'daqp {flag}'
        if flag < 1 or not np.isfinite(x).all():
            return None
        return np.asarray(x, dtype=float)

    def _run_osqp(self, key, P, q, A, S, lower, upper):
        """OSQP, one solver per key with the values updated in place.

        P: (n,) the diagonal of the objective. A: (m, n) with S (m, n) bool its structural
        non-zeros (fixed per key). Returns x or None.
        """
        entry = self._solvers.get(('osqp',) + key)
        fresh = entry is None
        n = len(q)
        if fresh:
            cols, rows = np.nonzero(S.T)        # column-major order
            indptr = np.concatenate([[0], np.cumsum(np.bincount(cols, minlength=n))])
            A_sp = sp.csc_matrix((A[rows, cols], rows, indptr), shape=A.shape)
            P_sp = sp.csc_matrix((P.copy(), np.arange(n), np.arange(n + 1)), shape=(n, n))
            solver = osqp.OSQP()
            solver.setup(P=P_sp, q=q, A=A_sp, l=lower, u=upper, verbose=False,
                         eps_abs=self.osqp_eps, eps_rel=self.osqp_eps,
                         max_iter=self.max_iter * 4, polishing=True, warm_starting=True,
                         adaptive_rho=True)
            entry = (solver, rows, cols)
            self._solvers[('osqp',) + key] = entry
        else:
            solver, rows, cols = entry
            solver.update(Px=P.copy(), q=q, Ax=A[rows, cols], l=lower, u=upper)
        try:
            res = solver.solve(raise_error=False)
        except Exception:  # noqa: BLE001 - an OSQP error is a solver failure
            self._solvers.pop(('osqp',) + key, None)
            return None
        x = np.asarray(res.x, dtype=float) if res.x is not None else None
        self.last_status = _status_name(res.info.status_val)
        status = res.info.status_val
        if (status == osqp.SolverStatus.OSQP_MAX_ITER_REACHED and x is not None
                and res.info.prim_res < 1e-4 and res.info.dual_res < 1e-3):
            status = osqp.SolverStatus.OSQP_SOLVED_INACCURATE   # feasible, nearly optimal
        ok = status in _OSQP_OK and x is not None and np.all(np.isfinite(x))
        if not ok:
            self._solvers.pop(('osqp',) + key, None)
            if not fresh:     # a warm start from a very different problem: one cold retry
                return self._run_osqp(key, P, q, A, S, lower, upper)
            return None
        return x

    def _run_proxqp(self, key, H, g, A, b, Cm, lo, up):
        n, n_eq, n_in = H.shape[0], A.shape[0], Cm.shape[0]
        qp = self._solvers.get(('proxqp',) + key)
        fresh = qp is None
        if fresh:
            qp = proxqp.dense.QP(n, n_eq, n_in)
            qp.settings.eps_abs = self.eps
            qp.settings.max_iter = self.max_iter
            qp.settings.initial_guess = proxqp.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            qp.settings.verbose = False
            qp.init(H, g, A, b, Cm, lo, up)
            self._solvers[('proxqp',) + key] = qp
        else:
            qp.update(H, g, A, b, Cm, lo, up)
        qp.solve()
        status = qp.results.info.status
        x = qp.results.x
        if status != proxqp.QPSolverOutput.PROXQP_SOLVED or not np.all(np.isfinite(x)):
            del self._solvers[('proxqp',) + key]
            if not fresh:     # a stale warm start can stall: one cold retry
                return self._run_proxqp(key, H, g, A, b, Cm, lo, up)
            return None, 'failed'
        return np.array(x, dtype=float), str(status).split('.')[-1]


def frame_drift(model, data, frame_ids: Sequence[int], reference) -> np.ndarray:
    """(C, 3) ``Jdot_c qd`` of each frame: its classical linear acceleration with qdd = 0.

    ``pinocchio.forwardKinematics(model, data, q, v, 0)`` must have run.
    """
    import pinocchio as pin
    return np.array([pin.getFrameClassicalAcceleration(model, data, f, reference).linear
                     for f in frame_ids])


__all__ = ['WholeBodyID', 'WbidResult', 'WbidUnavailable', 'stance_rows', 'frame_drift']
