"""Independent numpy formulation of the manipulator (fmus/manipulator) for cross-checks.

Same mechanism, different method: absolute body coordinates.  Each moving body 2..6
obeys the Newton-Euler equations at its centre of gravity,

    m_b a_b = f_b + (constraint forces),   I_b alpha_b + w_b x I_b w_b = t_b + (constraint torques),

and every joint (the five revolutes including the loop-closing one at A, and the
cylindrical joint 5-6) is written as acceleration-level constraints on the 30 absolute
accelerations, enforced with Lagrange multipliers.  The planar loop makes two of the
29 joint equations redundant; they are removed by an SVD of the constraint matrix
before the KKT system is solved.  Velocities come from complex-step differentiation of
the forward kinematics (exact to rounding), the loop closure from a closed form.

Units: SI (m, kg, s, rad, N, N m).  Parameters use the FMU's names (see
models/mechanism/parameters.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

EX, EY, EZ = np.eye(3)
CS_STEP = 1e-30  # complex-step size


def rodrigues(axis: np.ndarray, angle: complex | float) -> np.ndarray:
    """Rotation matrix by `angle` (rad, may be complex) about the unit vector `axis`."""
    k = np.asarray(axis, dtype=float)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * (K @ K)


def skew(r: np.ndarray) -> np.ndarray:
    """Matrix of the cross product r x (.)."""
    return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])


def vee(W: np.ndarray) -> np.ndarray:
    """Vector of a skew-symmetric matrix."""
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


@dataclass
class Pose:
    """Body rotations R[b] (body -> global) and frame origins p[b] for bodies b = 2..6, pin A."""

    R: dict[int, np.ndarray]
    p: dict[int, np.ndarray]
    A: np.ndarray


class Mechanism:
    """The manipulator in absolute coordinates, built from the FMU's parameter dictionary."""

    def __init__(self, params: dict[str, float]):
        self.par = dict(params)
        g = self.par
        self.j2 = np.array([0.0, g["j2_y"], g["j2_z"]])
        self.j3 = np.array([0.0, g["j3_y"], g["j3_z"]])
        self.j4 = np.array([0.0, g["j4_y"], g["j4_z"]])
        self.a3 = np.array([0.0, g["a3_y"], g["a3_z"]])
        self.grav = g["g"]
        table = self.pose(self.full_q([g["q1_table"], g["q2_table"], g["q3_table"]]))
        self.mass, self.cg_local, self.inertia_local = {}, {}, {}
        for b in range(2, 7):
            R, p = table.R[b], table.p[b]
            cg = np.array([g[f"cg{b}_x"], g[f"cg{b}_y"], g[f"cg{b}_z"]])
            self.mass[b] = g[f"m{b}"]
            self.cg_local[b] = R.T @ (cg - p)
            self.inertia_local[b] = R.T @ np.diag([g[f"Ixx{b}"], g[f"Iyy{b}"], g[f"Izz{b}"]]) @ R
        self.cyl = []  # (body_a, local a, body_b, local b)
        for c in (1, 2, 3):
            ends = []
            for e in ("a", "b"):
                body = int(g[f"cyl{c}_body_{e}"])
                x = np.array([g[f"cyl{c}_{e}x"], g[f"cyl{c}_{e}y"], g[f"cyl{c}_{e}z"]])
                ends += [body, x if body == 1 else table.R[body].T @ (x - table.p[body])]
            self.cyl.append(tuple(ends))
        q0 = self.full_q([g["q1_0"], g["q2_0"], g["q3_0"]])
        self.length0 = [self.cylinder_length(q0, c) for c in range(3)]

    # ---------------------------------------------------------------- kinematics
    def pose(self, q: np.ndarray) -> Pose:
        """Forward kinematics of the open tree for q1..q6 (real or complex)."""
        R, p = {}, {}
        R[2], p[2] = rodrigues(EZ, q[0]), np.zeros(3)
        R[3], p[3] = R[2] @ rodrigues(EX, q[1]), p[2] + R[2] @ self.j2
        R[4], p[4] = R[3] @ rodrigues(EX, q[2]), p[3] + R[3] @ self.j3
        R[5], p[5] = R[4] @ rodrigues(EX, q[3]), p[4] + R[4] @ self.j4
        R[6], p[6] = R[5] @ rodrigues(EY, q[5]), p[5] + q[4] * (R[5] @ EY)
        return Pose(R, p, p[3] + R[3] @ self.a3)

    def full_q(self, v) -> np.ndarray:
        """q1..q6 from v = (q1, q2, q3): the loop closed in closed form (strut from B to A)."""
        q = np.array([v[0], v[1], v[2], 0.0, 0.0, 0.0])
        P = self.pose(q)
        BA = P.A - P.p[5]
        local = P.R[4].T @ BA
        q[3] = np.arctan2(local[2], local[1])
        q[4] = np.linalg.norm(BA)
        return q

    def closure(self, q: np.ndarray) -> np.ndarray:
        """The closing revolute at A: body 6's origin on A, x6 parallel to x3 (5 equations)."""
        P = self.pose(q)
        x6 = P.R[6] @ EX
        return np.concatenate([P.p[6] - P.A, [x6 @ (P.R[3] @ EY), x6 @ (P.R[3] @ EZ)]])

    def full_qd(self, q: np.ndarray, vd) -> np.ndarray:
        """q-dot with u-dot from the velocity constraint (complex-step Jacobian of the closure)."""
        J = np.array([np.imag(self.closure(q + 1j * CS_STEP * e)) / CS_STEP for e in np.eye(6)]).T
        ud = np.linalg.lstsq(J[:, 3:], -J[:, :3] @ np.asarray(vd, dtype=float), rcond=None)[0]
        return np.concatenate([vd, ud])

    def body_velocities(self, q: np.ndarray, qd: np.ndarray):
        """Angular velocities and cg velocities of bodies 2..6, by complex step along qd."""
        P = self.pose(q)
        Pc = self.pose(q + 1j * CS_STEP * qd)
        w, v, c = {}, {}, {}
        for b in range(2, 7):
            Rdot = np.imag(Pc.R[b]) / CS_STEP
            w[b] = vee(Rdot @ P.R[b].T)
            c[b] = P.p[b] + P.R[b] @ self.cg_local[b]
            v[b] = np.imag(Pc.p[b] + Pc.R[b] @ self.cg_local[b]) / CS_STEP
        return P, w, v, c

    def cylinder_points(self, q: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Global attachment points (a, b) of cylinder k (0-based) at q (real or complex)."""
        P = self.pose(q)
        ba, xa, bb, xb = self.cyl[k]
        pa = xa if ba == 1 else P.p[ba] + P.R[ba] @ xa
        pb = xb if bb == 1 else P.p[bb] + P.R[bb] @ xb
        return pa, pb

    def cylinder_length(self, q: np.ndarray, k: int) -> float:
        """Distance between cylinder k's attachment points (m)."""
        pa, pb = self.cylinder_points(q, k)
        d = pb - pa
        return np.sqrt(d @ d)

    def cylinder_rate(self, q: np.ndarray, qd: np.ndarray, k: int) -> float:
        """Time derivative of cylinder k's length (m/s), by complex step."""
        return float(np.imag(self.cylinder_length(q + 1j * CS_STEP * qd, k)) / CS_STEP)

    # ---------------------------------------------------------------- energy
    def energy(self, v, vd) -> float:
        """Kinetic plus gravitational potential energy (J, z = 0 datum)."""
        q = self.full_q(v)
        qd = self.full_qd(q, vd)
        P, w, vel, c = self.body_velocities(q, qd)
        e = 0.0
        for b in range(2, 7):
            Ig = P.R[b] @ self.inertia_local[b] @ P.R[b].T
            e += (
                0.5 * self.mass[b] * vel[b] @ vel[b]
                + 0.5 * w[b] @ Ig @ w[b]
                + self.mass[b] * self.grav * c[b][2]
            )
        return float(e)

    def reduced_mass_matrix(self, v) -> np.ndarray:
        """M_bar from the kinetic energy T(vd) = vd' M_bar vd / 2 by polarization."""
        q = self.full_q(v)
        zero = self.energy(v, np.zeros(3))
        T = lambda vd: self.energy(v, vd) - zero  # noqa: E731
        M = np.zeros((3, 3))
        E = np.eye(3)
        for i in range(3):
            for j in range(3):
                M[i, j] = T(E[i] + E[j]) - T(E[i]) - T(E[j]) if i != j else 2 * T(E[i])
        del q
        return M

    # ---------------------------------------------------------------- dynamics
    def accelerations(self, v, vd, effort, disturbance, actuation: int, damping=(0.0, 0.0, 0.0)):
        """q1''..q3'' (rad/s^2) and body 6's cg acceleration (m/s^2) for state (v, vd).

        effort: joint torques (N m, actuation 0) or cylinder forces (N, actuation 1);
        disturbance: extra joint torques on q1..q3 (N m); damping: joint viscous damping (N m s/rad).
        """
        q = self.full_q(v)
        qd = self.full_qd(q, vd)
        P, w, vel, c = self.body_velocities(q, qd)
        idx = {b: 6 * (b - 2) for b in range(2, 7)}  # a_b at idx, alpha_b at idx + 3
        rows, rhs = [], []

        def point_terms(b, x):
            """Linear map z -> acceleration of point x on body b, and the velocity-product part."""
            r = x - c[b]
            Lm = np.zeros((3, 30))
            Lm[:, idx[b] : idx[b] + 3] = np.eye(3)
            Lm[:, idx[b] + 3 : idx[b] + 6] = -skew(r)
            return Lm, np.cross(w[b], np.cross(w[b], r))

        def point_velocity(b, x):
            return vel[b] + np.cross(w[b], x - c[b])

        def coincide(i, j, x):
            Lj, bj = point_terms(j, x)
            if i == 1:
                Li, bi = np.zeros((3, 30)), np.zeros(3)
            else:
                Li, bi = point_terms(i, x)
            rows.extend(Lj - Li)
            rhs.extend(-(bj - bi))

        def parallel(i, j, axis_i):
            """Relative angular velocity of j w.r.t. i along axis_i (fixed in body i) only."""
            wi = np.zeros(3) if i == 1 else w[i]
            for e in np.linalg.svd(axis_i.reshape(1, 3))[2][1:]:  # two unit vectors normal to the axis
                row = np.zeros(30)
                row[idx[j] + 3 : idx[j] + 6] = e
                if i != 1:
                    row[idx[i] + 3 : idx[i] + 6] = -e
                rows.append(row)
                rhs.append(-(w[j] - wi) @ np.cross(wi, e))

        coincide(1, 2, P.p[2])
        parallel(1, 2, EZ)
        for parent, child in ((2, 3), (3, 4), (4, 5)):
            coincide(parent, child, P.p[child])
            parallel(parent, child, P.R[parent] @ EX)
        coincide(3, 6, P.A)
        parallel(3, 6, P.R[3] @ EX)
        # cylindrical 5-6: body 6's origin stays on body 5's y axis through B
        d, B, X6 = P.R[5] @ EY, P.p[5], P.p[6]
        L6, b6 = point_terms(6, X6)
        LB, bB = point_terms(5, B)
        rel_v = point_velocity(6, X6) - point_velocity(5, B)
        for e in np.linalg.svd(d.reshape(1, 3))[2][1:]:
            row = e @ (L6 - LB)
            row[idx[5] + 3 : idx[5] + 6] += np.cross(e, X6 - B)
            rows.append(row)
            rhs.append(
                -(
                    e @ (b6 - bB)
                    + 2 * rel_v @ np.cross(w[5], e)
                    + (X6 - B) @ np.cross(w[5], np.cross(w[5], e))
                )
            )
        parallel(5, 6, d)
        C, gam = np.array(rows), np.array(rhs)
        U, S, Vt = np.linalg.svd(C, full_matrices=False)
        rank = int(np.sum(S > 1e-10 * S[0]))
        C, gam = S[:rank, None] * Vt[:rank], U[:, :rank].T @ gam

        # applied forces and the mass matrix in absolute coordinates
        Mabs, f = np.zeros((30, 30)), np.zeros(30)
        for b in range(2, 7):
            Ig = P.R[b] @ self.inertia_local[b] @ P.R[b].T
            Mabs[idx[b] : idx[b] + 3, idx[b] : idx[b] + 3] = self.mass[b] * np.eye(3)
            Mabs[idx[b] + 3 : idx[b] + 6, idx[b] + 3 : idx[b] + 6] = Ig
            f[idx[b] + 2] -= self.mass[b] * self.grav
            f[idx[b] + 3 : idx[b] + 6] -= np.cross(w[b], Ig @ w[b])

        def torque(parent, child, axis, tau):
            f[idx[child] + 3 : idx[child] + 6] += tau * axis
            if parent != 1:
                f[idx[parent] + 3 : idx[parent] + 6] -= tau * axis

        def force(b, x, F):
            if b == 1:
                return
            f[idx[b] : idx[b] + 3] += F
            f[idx[b] + 3 : idx[b] + 6] += np.cross(x - c[b], F)

        joints = ((1, 2, EZ), (2, 3, P.R[2] @ EX), (3, 4, P.R[3] @ EX))
        for k, (parent, child, axis) in enumerate(joints):
            tau = disturbance[k] - damping[k] * qd[k] + (effort[k] if actuation == 0 else 0.0)
            torque(parent, child, axis, tau)
        if actuation == 1:
            for k in range(3):
                pa, pb = self.cylinder_points(q, k)
                e = (pb - pa) / np.linalg.norm(pb - pa)
                force(self.cyl[k][2], pb, effort[k] * e)
                force(self.cyl[k][0], pa, -effort[k] * e)

        n = C.shape[0]
        K = np.block([[Mabs, C.T], [C, np.zeros((n, n))]])
        z = np.linalg.solve(K, np.concatenate([f, gam]))[:30]
        alpha = {b: z[idx[b] + 3 : idx[b] + 6] for b in range(2, 7)}
        x2, x3 = P.R[2] @ EX, P.R[3] @ EX
        qdd = np.array(
            [
                alpha[2] @ EZ,
                (alpha[3] - alpha[2]) @ x2 + (w[3] - w[2]) @ np.cross(w[2], x2),
                (alpha[4] - alpha[3]) @ x3 + (w[4] - w[3]) @ np.cross(w[3], x3),
            ]
        )
        return qdd, z[idx[6] : idx[6] + 3]
