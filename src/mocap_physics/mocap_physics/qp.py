"""The two quadratic programs of the dynamic cycle, solved with OSQP's own API (no ROS, no cvxpy).

Both keep one warm-started OSQP solver per active set of contact points: the sparsity pattern
of P and A is fixed for a given set, so a frame only updates numbers (``update(Px=, q=)``) and
solves; a new set builds (and caches) a new solver. The formulations are restated with cvxpy in
``test/test_qp.py``, which checks these solvers against them.

Ground reaction forces (neural PhysCap eq. 8, 9, 11), :class:`GrfQP`
    variables: lambda_c in R^3 for each active contact point c, world (floor) frame, z up
    minimise   || tau_root - J_1^T lambda ||_Wm^2 + w_s || lambda - lambda_prev ||^2
               + w_r ||lambda||^2
    subject to lambda_c,z >= 0,  |lambda_c,x| <= mu' lambda_c,z,  |lambda_c,y| <= mu' lambda_c,z
  ``J_1^T lambda`` = sum_c J_c[:, :6]^T lambda_c is the generalised root force that the contact
  forces produce (``J_c``: 3 x nv linear Jacobian of the contact point, world-aligned axes).
  ``Wm = diag(1, 1, 1, w_m, w_m, w_m)`` weighs the root moment (N m) against the root force
  (N); eq. 8 is w_m = 1 (``grf_moment_weight`` of the cycle, default 1; see
  ``docs/physics.md``). The friction cone of eq. 9 (mu = 0.8) is replaced by its inscribed
  four-sided pyramid, mu' = mu / sqrt(2): every force inside the pyramid is inside the true
  cone (conservative).
  The problem is solved in units of body weight (lambda / m g) for good conditioning; w_s
  (temporal smoothness, eq. 11, relative to the residual term) and a tiny w_r (makes the problem
  strictly convex; picks the least internal force) are dimensionless. The solution is finally
  projected onto the pyramid, so a reported force never leaves it by solver tolerance.

Penetration (neural PhysCap eq. 15-16), :class:`PenetrationQP`
    minimise   1/2 || qdot* - qdot ||_W^2
    subject to A qdot* >= b
  W = I (the plain norm of eq. 15, this class's default), W = M(q) (kinetic-energy metric) or
  W = diag(M(q)) (the cycle's default, ``penetration_metric``; the choice: ``docs/physics.md``),
  with one row per contact point near the floor: ``A_c = J_c,z`` (vertical velocity of the
  point) and ``b_c = min(-z_c / dt, v_recover)``: a point at or below the floor may not move
  down (and climbs back at most at ``v_recover``), a point above it may not cross it within the
  step (z + dt zdot >= 0). With W = M the correction ``qdot* - qdot = M^-1 A^T y`` is the
  velocity change of vertical contact impulses ``y >= 0`` (an inelastic impact on a passive
  body). OSQP solves the dual, which has one variable per row (at most 4) instead of nv:
    minimise   1/2 y^T (A W^-1 A^T) y + (A qdot - b)^T y    subject to  y >= 0
  and ``qdot* = qdot + W^-1 A^T y``. When ``qdot`` already satisfies every row, it is the
  solution and no solver runs.

  Foot stick (optional equality rows ``E qdot* = e``, :meth:`PenetrationQP.solve` ``A_eq``):
  the horizontal velocity of a contact point in contact, ``E_c = J_c,xy``, equals a small
  velocity ``e_c`` that holds it at its anchor on the floor (a no-slip condition in the same
  velocity-level form as eq. 15-16). Their dual variables z are free (y >= 0 stays for the
  inequality rows): ``qdot* = qdot + W^-1 (A^T y + E^T z)``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

import numpy as np
import osqp
import scipy.sparse as sp

try:
    import daqp
except ImportError:  # pragma: no cover - OSQP (then Clarabel) solve the dual alone
    daqp = None

#: Inscribed pyramid: |lambda_t|_inf <= mu lambda_n / sqrt(2) => |lambda_t|_2 <= mu lambda_n.
PYRAMID_FACTOR = 1.0 / np.sqrt(2.0)

_OSQP_OK = {osqp.SolverStatus.OSQP_SOLVED, osqp.SolverStatus.OSQP_SOLVED_INACCURATE}


def _status_name(status) -> str:
    try:
        return osqp.SolverStatus(status).name
    except Exception:  # pragma: no cover - unknown codes
        return str(status)


def _dense_triu_csc(n: int) -> Tuple[sp.csc_matrix, np.ndarray, np.ndarray]:
    """A CSC matrix with every upper-triangular entry stored (pattern fixed for updates) and
    the (row, col) index of each stored value in storage order."""
    rows, cols = np.triu_indices(n)
    order = np.lexsort((rows, cols))  # CSC: column major, rows ascending
    rows, cols = rows[order], cols[order]
    mat = sp.csc_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    mat.sort_indices()
    return mat, rows, cols


@dataclass
class GrfResult:
    """Solution of one GRF problem.

    forces: (C, 3) contact force of every contact point in the floor frame, N (zero when
        not in contact).
    residual: (6,) tau_root - J_1^T lambda, the direct root actuation left unexplained
        (force N and moment N m, root frame).
    ok: the solver converged (or there was nothing to solve).
    status: solver status text.
    solve_time: seconds spent in the solver (0 when nothing was solved).
    """

    forces: np.ndarray
    residual: np.ndarray
    ok: bool = True
    status: str = 'no_contact'
    solve_time: float = 0.0


class GrfQP:
    """Ground-reaction-force QP (module docstring), one instance per physics cycle.

    Args:
        num_contacts: number of contact points C.
        friction: Coulomb friction coefficient mu of eq. 9.
        smoothness: weight w_s of the temporal smoothness term (eq. 11).
        regularization: weight w_r of ||lambda||^2 (keeps the QP strictly convex).
    """

    def __init__(self, num_contacts: int = 4, friction: float = 0.8, smoothness: float = 0.1,
                 regularization: float = 1e-4, eps: float = 1e-6, max_iter: int = 2000,
                 moment_weight: float = 1.0) -> None:
        if not friction > 0:
            raise ValueError(f'friction coefficient must be positive, got {friction}')
        if smoothness < 0 or regularization <= 0:
            raise ValueError('smoothness must be >= 0 and regularization > 0')
        self.num_contacts = num_contacts
        self.friction = float(friction)
        self.mu_pyramid = self.friction * PYRAMID_FACTOR
        self.smoothness = float(smoothness)
        if not moment_weight > 0:
            raise ValueError('moment_weight must be positive')
        #: weight of the root-moment rows of the residual relative to the force rows
        self.row_weights = np.sqrt(np.array([1.0, 1.0, 1.0] + [float(moment_weight)] * 3))
        self.regularization = float(regularization)
        self.settings = dict(verbose=False, eps_abs=eps, eps_rel=eps, max_iter=max_iter,
                             polishing=False, warm_starting=True, adaptive_rho=True)
        self._solvers: Dict[Tuple[bool, ...], Tuple[osqp.OSQP, np.ndarray, np.ndarray]] = {}
        self.prev = np.zeros((num_contacts, 3))   # previous forces, units of body weight
        self.failures = 0
        self.solves = 0
        self.iterations = 0

    def reset(self) -> None:
        """Forget the previous forces (after a re-initialisation)."""
        self.prev[:] = 0.0

    def pyramid_matrix(self, n_active: int) -> sp.csc_matrix:
        """Constraint matrix G (5 n x 3 n): G lambda >= 0 is the friction pyramid."""
        m = self.mu_pyramid
        block = np.array([[0.0, 0.0, 1.0],
                          [-1.0, 0.0, m], [1.0, 0.0, m],
                          [0.0, -1.0, m], [0.0, 1.0, m]])
        return sp.csc_matrix(sp.block_diag([block] * n_active, format='csc'))

    def _solver(self, active: Tuple[bool, ...]):
        entry = self._solvers.get(active)
        if entry is None:
            n = 3 * sum(active)
            P, rows, cols = _dense_triu_csc(n)
            G = self.pyramid_matrix(sum(active))
            solver = osqp.OSQP()
            solver.setup(P=P, q=np.zeros(n), A=G, l=np.zeros(G.shape[0]),
                         u=np.full(G.shape[0], np.inf), **self.settings)
            entry = (solver, rows, cols)
            self._solvers[active] = entry
        return entry

    def project(self, forces: np.ndarray) -> np.ndarray:
        """Project forces (C, 3) onto the friction pyramid (exact feasibility)."""
        out = np.array(forces, dtype=float)
        out[:, 2] = np.maximum(out[:, 2], 0.0)
        lim = self.mu_pyramid * out[:, 2]
        out[:, 0] = np.clip(out[:, 0], -lim, lim)
        out[:, 1] = np.clip(out[:, 1], -lim, lim)
        return out

    def solve(self, tau_root: np.ndarray, root_jacobians: np.ndarray, active: np.ndarray,
              weight: float) -> GrfResult:
        """Solve for the contact forces.

        Args:
            tau_root: (6,) root part of the PD force vector (eq. 7), root frame.
            root_jacobians: (C, 3, 6) J_c[:, :6] of every contact point (world-aligned rows).
            active: (C,) bool, contact points in contact.
            weight: body weight m g, N (the solver's unit of force).
        """
        tau_root = np.asarray(tau_root, dtype=float)
        active_t = tuple(bool(a) for a in active)
        forces = np.zeros((self.num_contacts, 3))
        if not any(active_t):
            self.prev[:] = 0.0
            return GrfResult(forces, tau_root.copy())
        idx = np.flatnonzero(active_t)
        # A = J_1^T restricted to the active contacts: (6, 3 n)
        A = np.concatenate([root_jacobians[c].T for c in idx], axis=1)
        r0 = tau_root / weight
        x_prev = self.prev[idx].reshape(-1)
        w = self.smoothness + self.regularization
        Aw = A * self.row_weights[:, None]
        H = Aw.T @ Aw
        H[np.diag_indices_from(H)] += w
        solver, rows, cols = self._solver(active_t)
        P_x = 2.0 * H[rows, cols]
        q = -2.0 * (Aw.T @ (self.row_weights * r0) + self.smoothness * x_prev)
        t0 = time.perf_counter()
        try:
            solver.update(q=q, Px=P_x)
            solver.warm_start(x=x_prev)
            res = solver.solve(raise_error=False)
            status_val = res.info.status_val
            x = np.asarray(res.x, dtype=float)
            status_text = _status_name(status_val)
            self.iterations = int(res.info.iter)
            if (status_val == osqp.SolverStatus.OSQP_MAX_ITER_REACHED
                    and res.info.prim_res < 1e-4 and res.info.dual_res < 1e-3):
                # a feasible (after projection), nearly optimal iterate: use it
                status_val = osqp.SolverStatus.OSQP_SOLVED_INACCURATE
        except Exception as exc:  # an OSQP error is a solver failure, not a crash
            status_val, x = None, None
            status_text = f'error: {exc}'
        dt = time.perf_counter() - t0
        self.solves += 1
        ok = (status_val in _OSQP_OK and x is not None and x.shape == (3 * len(idx),)
              and bool(np.all(np.isfinite(x))))
        if not ok:
            self.failures += 1
            self.prev[:] = 0.0
            return GrfResult(forces, tau_root.copy(), ok=False, status=status_text,
                             solve_time=dt)
        forces[idx] = x.reshape(-1, 3)
        forces = self.project(forces)
        self.prev[:] = forces
        forces *= weight
        residual = tau_root - A @ forces[idx].reshape(-1)
        return GrfResult(forces, residual, ok=True, status=status_text, solve_time=dt)


@dataclass
class PenetrationResult:
    """Solution of one penetration problem.

    velocity: (nv,) corrected generalised velocity qdot*.
    impulses: (R,) dual variables y (vertical contact impulses, N s with the mass metric)
        of the rows passed in (zero where a row is inactive).
    ok: solved (or nothing to solve); status: solver status text.
    solved: a QP was solved (False when qdot was already feasible).
    """

    velocity: np.ndarray
    impulses: np.ndarray
    ok: bool = True
    status: str = 'feasible'
    solved: bool = False
    solve_time: float = 0.0
    max_violation: float = 0.0


@dataclass
class PenetrationQP:
    """Penetration QP (module docstring), solved through its dual with OSQP.

    Args:
        metric: 'identity' (W = I, the paper's plain norm), 'mass' (W = M(q)) or 'diagonal'
            (W = diag M(q)); the caller passes the matching ``solve_metric``.
        tolerance: allowed constraint violation of the result, m/s.
    """

    metric: str = 'identity'
    tolerance: float = 1e-6
    eps: float = 1e-9
    max_iter: int = 400
    failures: int = 0
    solves: int = 0
    second_chances: int = 0
    _solvers: Dict[Tuple[int, int], Tuple[osqp.OSQP, np.ndarray, np.ndarray]] = \
        field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.metric not in ('mass', 'diagonal', 'identity'):
            raise ValueError(f"metric must be 'mass', 'diagonal' or 'identity', got "
                             f"{self.metric!r}")

    def _solver(self, m: int, m_eq: int = 0):
        key = (m, m_eq)
        entry = self._solvers.get(key)
        if entry is None:
            n = m + m_eq
            P, rows, cols = _dense_triu_csc(n)
            solver = osqp.OSQP()
            lower = np.concatenate([np.zeros(m), np.full(m_eq, -np.inf)])
            solver.setup(P=P, q=np.zeros(n), A=sp.identity(n, format='csc'), l=lower,
                         u=np.full(n, np.inf), verbose=False, eps_abs=self.eps,
                         eps_rel=self.eps, max_iter=self.max_iter, polishing=False,
                         warm_starting=True)
            entry = (solver, rows, cols)
            self._solvers[key] = entry
        return entry

    @staticmethod
    def _daqp(P: np.ndarray, q: np.ndarray, m_eq: int):
        """The dual with DAQP: y_I >= 0 as simple bounds, the last ``m_eq`` variables free.
        Returns (y, OSQP-style status value or None, status text)."""
        n = len(q)
        lower = np.zeros(n)
        lower[n - m_eq:] = -1e30
        try:
            y, _, flag, _ = daqp.solve(P, q, np.zeros((0, n)), np.full(n, 1e30), lower,
                                       np.zeros(n, dtype=np.int32))
        except Exception as exc:  # noqa: BLE001 - a solver error is a failure
            return None, None, f'daqp error: {exc}'
        if flag < 1 or not np.isfinite(y).all():
            return None, None, f'daqp {flag}'
        return np.asarray(y, dtype=float), osqp.SolverStatus.OSQP_SOLVED, 'daqp solved'

    @staticmethod
    def _clarabel(P: np.ndarray, q: np.ndarray, m_eq: int):
        """The dual with Clarabel (interior point): the fallback when OSQP does not converge
        (ill-conditioned rows, e.g. heel and toe of one foot). Returns (y, status text)."""
        import clarabel
        n = len(q)
        m = n - m_eq
        settings = clarabel.DefaultSettings()
        settings.verbose = False
        # constraints: -y_I + s = 0, s >= 0 (y_I >= 0); the equality duals are free
        A = sp.csc_matrix(-np.eye(n)[:m]) if m else sp.csc_matrix((0, n))
        cones = [clarabel.NonnegativeConeT(m)] if m else []
        solver = clarabel.DefaultSolver(sp.csc_matrix(np.triu(P)), q, A, np.zeros(m), cones,
                                        settings)
        sol = solver.solve()
        ok = str(sol.status) in ('Solved', 'AlmostSolved', 'SolverStatus.Solved',
                                 'SolverStatus.AlmostSolved')
        return (np.asarray(sol.x, dtype=float) if ok else None), f'clarabel {sol.status}'

    @staticmethod
    def _refine(y: np.ndarray, P: np.ndarray, q: np.ndarray, m_eq: int = 0) -> np.ndarray:
        """Exact solution on the support set found by OSQP (our own 'polishing', which OSQP
        would print about): solve P_SS y_S = -q_S; keep it if it satisfies the KKT conditions
        (y >= 0, P y + q >= 0 off the support). The last ``m_eq`` variables are free (always
        in the support)."""
        m = len(y) - m_eq
        free = np.zeros(len(y), dtype=bool)
        free[m:] = True
        support = free | (y > 1e-9 * max(1.0, float(np.abs(y).max(initial=0.0))))
        if not support.any():
            return y
        y_ref = np.zeros_like(y)
        try:
            y_ref[support] = np.linalg.solve(P[np.ix_(support, support)], -q[support])
        except np.linalg.LinAlgError:
            return y
        grad = P @ y_ref + q
        if np.all(y_ref[:m] >= 0.0) and np.all(grad[~support] >= -1e-9):
            return y_ref
        return y

    def solve(self, velocity: np.ndarray, A: np.ndarray, b: np.ndarray,
              solve_metric=None, scale: float = 1.0, A_eq: Optional[np.ndarray] = None,
              b_eq: Optional[np.ndarray] = None) -> PenetrationResult:
        """Closest velocity to ``velocity`` with ``A v >= b`` (and ``A_eq v = b_eq``).

        Args:
            velocity: (nv,) the velocity after the dynamics update.
            A: (R, nv) constraint rows; b: (R,) bounds (R may be 0).
            solve_metric: callable X -> W^-1 X for (nv, k) X (the mass metric; e.g. a Cholesky
                solve); None for the identity metric.
            scale: a typical value of W (body mass for the mass metric) used to scale the dual.
            A_eq, b_eq: optional (E, nv) equality rows and (E,) values (the foot stick).
        The ``impulses`` of the result hold the R inequality duals, then the E equality ones.
        """
        v = np.asarray(velocity, dtype=float)
        A = np.asarray(A, dtype=float).reshape(-1, v.size)
        b = np.asarray(b, dtype=float).reshape(-1)
        if A_eq is None:
            E, e = np.zeros((0, v.size)), np.zeros(0)
        else:
            E = np.asarray(A_eq, dtype=float).reshape(-1, v.size)
            e = np.asarray(b_eq, dtype=float).reshape(-1)
        m, m_eq = A.shape[0], E.shape[0]
        slack = A @ v - b
        eq_res = E @ v - e
        if (m == 0 or (slack >= -self.tolerance).all()) and \
                (m_eq == 0 or (np.abs(eq_res) <= self.tolerance).all()):
            return PenetrationResult(v.copy(), np.zeros(m + m_eq))
        G = np.concatenate([A, E]) if m_eq else A
        q = np.concatenate([slack, eq_res]) if m_eq else slack
        WinvGt = G.T.copy() if solve_metric is None else solve_metric(G.T)
        D = G @ WinvGt
        D = 0.5 * (D + D.T)
        D.reshape(-1)[::D.shape[0] + 1] += 1e-10 * max(D.trace(), 1e-12)
        t0 = time.perf_counter()
        status_val, y, status_text = None, None, 'daqp missing'
        def violation(vel: np.ndarray) -> float:
            return float(max(0.0, -(A @ vel - b).min(initial=0.0),
                             np.abs(E @ vel - e).max(initial=0.0)))

        tol = max(self.tolerance, 1e-4)
        exact = None                    # (velocity, impulses, violation) of a DAQP answer
        if daqp is not None:
            # DAQP first: a dual active-set solver, exact on its active set, deterministic
            y, status_val, status_text = self._daqp(scale * D, q, m_eq)
            if y is not None:
                # an ill-conditioned dual (dependent rows) can end off the constraints:
                # then the other solvers have their turn
                y = np.concatenate([np.maximum(y[:m], 0.0), y[m:]]) * scale
                v_try = v + WinvGt @ y
                off = violation(v_try)
                if off > tol:
                    status_val, y = None, None
                    status_text = f'daqp solved off the constraints ({off:.1e} m/s)'
                else:
                    exact = (v_try, y, off)
        if status_val not in _OSQP_OK:
            solver, rows, cols = self._solver(m, m_eq)
            try:
                x0 = np.concatenate([np.maximum(-slack, 0.0), -eq_res])
                solver.update(q=q, Px=scale * D[rows, cols])
                solver.warm_start(x=x0 / max(np.diag(scale * D).max(), 1e-12))
                res = solver.solve(raise_error=False)
                status_val = res.info.status_val
                y = np.asarray(res.x, dtype=float)
                status_text = f'{status_text}, then {_status_name(status_val)}'
            except Exception as exc:
                status_val, y, status_text = None, None, f'{status_text}, then error: {exc}'
        if status_val not in _OSQP_OK or y is None or not np.isfinite(y).all():
            # second chance: Clarabel on the same dual (scaled the same way)
            try:
                y, text = self._clarabel(scale * D, q, m_eq)
            except Exception as exc:  # pragma: no cover - solver errors are failures
                y, text = None, f'clarabel error: {exc}'
            status_text = f'{status_text}, then {text}'
            if y is not None and np.isfinite(y).all():
                status_val = osqp.SolverStatus.OSQP_SOLVED
                self.second_chances += 1
        dt = time.perf_counter() - t0
        self.solves += 1
        viol0 = float(max(0.0, -slack.min(initial=0.0), np.abs(eq_res).max(initial=0.0)))
        if status_val not in _OSQP_OK or y is None or not np.isfinite(y).all():
            self.failures += 1
            return PenetrationResult(v.copy(), np.zeros(m + m_eq), ok=False, status=status_text,
                                     solved=True, solve_time=dt, max_violation=viol0)
        if exact is not None:                           # DAQP is exact on its active set
            v_new, y, viol = exact
        else:
            y[:m] = np.maximum(y[:m], 0.0)
            y = self._refine(y, scale * D, q, m_eq) * scale   # the solver's variable: y / scale
            v_new = v + WinvGt @ y
            viol = violation(v_new)
        if viol > tol:
            self.failures += 1
            return PenetrationResult(v_new, y, ok=False, status=f'{status_text} (violation '
                                     f'{viol:.2e} m/s)', solved=True, solve_time=dt,
                                     max_violation=viol)
        return PenetrationResult(v_new, y, ok=True, status=status_text, solved=True,
                                 solve_time=dt, max_violation=viol)
