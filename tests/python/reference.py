"""A plain NumPy reference of lidarcal's numerical kernels, for parity tests.

Written independently of the Rust code and from the textbook formulas: Kabsch by SVD, the SO(3)
logarithm by atan2 with a separate branch near pi, SE(3) exp/log by the closed-form left Jacobian,
the point-to-plane and point-to-line residuals with their left-perturbation Jacobians, and a
solve of the same alignment problems with SciPy's ``least_squares`` (finite-difference Jacobian,
so it shares nothing with the analytic one).

Conventions match lidarcal: ``T = reference_from_target``; twists are ``[rho, phi]``;
perturbations act on the left, ``T <- exp(delta) @ T``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.optimize import least_squares


def hat(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def vee(m: np.ndarray) -> np.ndarray:
    return np.array([m[2, 1], m[0, 2], m[1, 0]])


def so3_exp(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    k = hat(phi)
    if theta < 1e-8:
        return np.eye(3) + k + 0.5 * k @ k
    return np.eye(3) + np.sin(theta) / theta * k + 2 * np.sin(theta / 2) ** 2 / theta**2 * k @ k


def so3_log(r: np.ndarray) -> np.ndarray:
    w = vee(r - r.T)  # = 2 sin(theta) axis
    s = 0.5 * np.linalg.norm(w)
    c = 0.5 * (np.trace(r) - 1.0)
    theta = np.arctan2(s, c)
    if theta < 1e-8:
        return 0.5 * w
    if theta < np.pi - 1e-4:
        return theta / (2.0 * np.sin(theta)) * w
    # Near pi: (R + R^T)/2 - c I = (1 - c) a a^T; take the best-conditioned column.
    b = 0.5 * (r + r.T) - c * np.eye(3)
    k = int(np.argmax(np.diag(b)))
    a = b[:, k] / np.sqrt(b[k, k] * (1.0 - c))
    if a @ w < 0:
        a = -a
    return theta * a / np.linalg.norm(a)


def left_jacobian(phi: np.ndarray) -> np.ndarray:
    theta = float(np.linalg.norm(phi))
    k = hat(phi)
    if theta < 1e-6:
        return np.eye(3) + 0.5 * k + k @ k / 6.0
    # 1 - cos(t) written as 2 sin^2(t/2): the direct form loses ~1e-16/t^2 to cancellation.
    return (
        np.eye(3)
        + 2 * np.sin(theta / 2) ** 2 / theta**2 * k
        + (theta - np.sin(theta)) / theta**3 * k @ k
    )


def se3_exp(xi: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = so3_exp(xi[3:])
    t[:3, 3] = left_jacobian(xi[3:]) @ xi[:3]
    return t


def se3_log(t: np.ndarray) -> np.ndarray:
    phi = so3_log(t[:3, :3])
    rho = np.linalg.solve(left_jacobian(phi), t[:3, 3])
    return np.concatenate([rho, phi])


def rotation_angle(r: np.ndarray) -> float:
    """Angle of a rotation matrix, accurate near 0 (atan2 of the skew and symmetric parts)."""
    return float(np.arctan2(0.5 * np.linalg.norm(vee(r - r.T)), 0.5 * (np.trace(r) - 1.0)))


def kabsch(a: np.ndarray, b: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """R minimising sum w |R b - a|^2."""
    w = np.ones(len(a)) if w is None else np.asarray(w, dtype=float)
    h = (a * w[:, None]).T @ b
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The basis lidarcal uses for point-to-line residuals (Duff et al. 2017)."""
    sign = np.copysign(1.0, n[2])
    a = -1.0 / (sign + n[2])
    b = n[0] * n[1] * a
    b1 = np.array([1.0 + sign * n[0] ** 2 * a, sign * b, -sign * n[0]])
    b2 = np.array([b, sign + n[1] ** 2 * a, -n[1]])
    return b1, b2


def transform_points(t: np.ndarray, p: np.ndarray) -> np.ndarray:
    return p @ t[:3, :3].T + t[:3, 3]


def plane_residuals(
    points: np.ndarray, plane: np.ndarray, t: np.ndarray, frame: str = "target"
) -> tuple[np.ndarray, np.ndarray]:
    """r (N,) and J (N, 6) of points against a plane [n, d] (left perturbation of t)."""
    n, d = plane[:3] / np.linalg.norm(plane[:3]), plane[3] / np.linalg.norm(plane[:3])
    if frame == "target":
        q = transform_points(t, points)
        r = q @ n + d
        j = np.hstack([np.tile(n, (len(q), 1)), np.cross(q, n)])
    else:
        m = t[:3, :3] @ n
        r = points @ m + d - m @ t[:3, 3]
        j = np.hstack([np.tile(-m, (len(points), 1)), np.cross(m, points)])
    return r, j


def line_residuals(
    points: np.ndarray, line: np.ndarray, t: np.ndarray, frame: str = "target"
) -> tuple[np.ndarray, np.ndarray]:
    """r (N, 2) and J (N, 2, 6) of points against a line [p, u] (left perturbation of t)."""
    c, u = line[:3], line[3:] / np.linalg.norm(line[3:])
    e1, e2 = orthonormal_basis(u)
    if frame == "target":
        q = transform_points(t, points)
        basis = np.stack([e1, e2])
        r = (q - c) @ basis.T
        j = np.stack([np.hstack([np.tile(e, (len(q), 1)), np.cross(q, e)]) for e in basis], axis=1)
    else:
        basis = np.stack([t[:3, :3] @ e1, t[:3, :3] @ e2])
        c_ref = t[:3, :3] @ c + t[:3, 3]
        r = (points - c_ref) @ basis.T
        j = np.stack(
            [np.hstack([np.tile(-e, (len(points), 1)), np.cross(e, points)]) for e in basis],
            axis=1,
        )
    return r, j


def numeric_jacobian(f, t: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of f(T) (any shape) w.r.t. the left perturbation; last axis is 6."""
    cols = []
    for i in range(6):
        d = np.zeros(6)
        d[i] = h
        cols.append((f(se3_exp(d) @ t) - f(se3_exp(-d) @ t)) / (2 * h))
    return np.stack(cols, axis=-1)


def robust_rho(s: np.ndarray, loss: str, scale: float) -> np.ndarray:
    """rho(s) of SciPy's least_squares for s = r^2 with f_scale = scale."""
    if loss == "squared":
        return s
    z = s / scale**2
    if loss == "huber":
        return scale**2 * np.where(z <= 1, z, 2 * np.sqrt(z) - 1)
    if loss == "cauchy":
        return scale**2 * np.log1p(z)
    raise ValueError(loss)


def plane_cost(
    t: np.ndarray,
    planes: np.ndarray,
    points: Sequence[np.ndarray],
    frames: Sequence[str],
    loss: str = "squared",
    scale: float = 1.0,
) -> float:
    r = np.concatenate(
        [plane_residuals(p, pl, t, f)[0] for pl, p, f in zip(planes, points, frames, strict=False)]
    )
    return float(0.5 * np.sum(robust_rho(r**2, loss, scale)))


def line_cost(
    t: np.ndarray,
    lines: np.ndarray,
    points: Sequence[np.ndarray],
    frames: Sequence[str],
    loss: str = "squared",
    scale: float = 1.0,
) -> float:
    s = np.concatenate(
        [
            np.sum(line_residuals(p, ln, t, f)[0] ** 2, axis=1)
            for ln, p, f in zip(lines, points, frames, strict=False)
        ]
    )
    return float(0.5 * np.sum(robust_rho(s, loss, scale)))


def _pose(x: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = so3_exp(x[3:])
    t[:3, 3] = x[:3]
    return t


def solve_planes(
    planes: np.ndarray,
    points: Sequence[np.ndarray],
    frames: Sequence[str],
    initial: np.ndarray,
    loss: str = "squared",
    scale: float = 1.0,
) -> tuple[np.ndarray, float]:
    """Minimise the point-to-plane cost with SciPy (rotation vector + translation parameters)."""

    def fun(x: np.ndarray) -> np.ndarray:
        t = _pose(x)
        return np.concatenate(
            [
                plane_residuals(p, pl, t, f)[0]
                for pl, p, f in zip(planes, points, frames, strict=False)
            ]
        )

    x0 = np.concatenate([initial[:3, 3], so3_log(initial[:3, :3])])
    sol = least_squares(
        fun,
        x0,
        method="trf",
        loss="linear" if loss == "squared" else loss,
        f_scale=scale,
        jac="3-point",
        ftol=1e-15,
        xtol=1e-15,
        gtol=1e-15,
        max_nfev=2000,
    )
    t = _pose(sol.x)
    return t, plane_cost(t, planes, points, frames, loss, scale)


def solve_lines(
    lines: np.ndarray,
    points: Sequence[np.ndarray],
    frames: Sequence[str],
    initial: np.ndarray,
) -> tuple[np.ndarray, float]:
    """Least-squares point-to-line alignment with SciPy."""

    def fun(x: np.ndarray) -> np.ndarray:
        t = _pose(x)
        return np.concatenate(
            [
                line_residuals(p, ln, t, f)[0].ravel()
                for ln, p, f in zip(lines, points, frames, strict=False)
            ]
        )

    x0 = np.concatenate([initial[:3, 3], so3_log(initial[:3, :3])])
    sol = least_squares(fun, x0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=5000)
    t = _pose(sol.x)
    return t, line_cost(t, lines, points, frames)


# --- RANSAC -------------------------------------------------------------------------------


def bbox_center(points: np.ndarray) -> np.ndarray:
    """The bounding-box midpoint lidarcal centres its f32 scoring copy on."""
    return (points.min(axis=0) + points.max(axis=0)) * 0.5


def _unit_plane(plane: np.ndarray) -> tuple[float, float, float, float]:
    """Normalise like lidarcal (norm = sqrt(x*x + y*y + z*z), in that order)."""
    a, b, c, d = (float(v) for v in plane)
    norm = np.sqrt(a * a + b * b + c * c)
    return a / norm, b / norm, c / norm, d / norm


def score_planes_f32(
    points: np.ndarray, planes: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """MSAC cost and inlier count of each plane, emulating lidarcal's f32 arithmetic exactly
    (same centring, same operation order) so the inlier counts match bit for bit."""
    center = bbox_center(points[:, :3])
    x, y, z = ((points[:, i] - center[i]).astype(np.float32) for i in range(3))
    t2 = np.float32(threshold) * np.float32(threshold)
    costs, counts = [], []
    for plane in planes:
        a, b, c, d = _unit_plane(plane)
        d_centred = d + (a * center[0] + b * center[1] + c * center[2])
        a32, b32, c32, d32 = (np.float32(v) for v in (a, b, c, d_centred))
        dist = a32 * x + b32 * y + c32 * z + d32
        d2 = dist * dist
        inside = d2 < t2
        costs.append(float(np.sum(np.where(inside, d2, t2).astype(np.float64))))
        counts.append(int(inside.sum()))
    return np.array(costs), np.array(counts)


def fit_plane(points: np.ndarray) -> np.ndarray:
    """Total-least-squares plane [n, d] (normal toward the origin) by SVD."""
    mean = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mean)
    n = vt[2]
    d = -n @ mean
    return np.concatenate([n, [d]]) if d >= 0 else -np.concatenate([n, [d]])


def fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Total-least-squares line (mean, unit direction) by SVD."""
    mean = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - mean)
    return mean, vt[0]


def corner_cloud(
    rng: np.random.Generator, n_per_plane: int, clutter: int, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Three planes of a wall corner (sampled up to the intersection lines) plus clutter.
    Returns (points (N, 3), true planes (3, 4) with normals toward the origin)."""
    corner = np.array([6.0, 4.0, -1.5])
    normals = np.array([[-1.0, -0.2, 0.0], [-0.3, -1.0, 0.05], [0.02, 0.0, 1.0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    planes = np.hstack([normals, -(normals @ corner)[:, None]])
    pts = []
    for k in range(3):
        others = [j for j in range(3) if j != k]
        edges = []
        for o, other in zip(others, reversed(others), strict=True):
            e = np.cross(normals[k], normals[o])
            e /= np.linalg.norm(e)
            # Point the edge to the sensor side of the remaining plane.
            if planes[other, :3] @ (corner + e) + planes[other, 3] < 0:
                e = -e
            edges.append(e)
        ab = rng.uniform(0.0, 4.0, (n_per_plane, 2))
        noise = rng.normal(0.0, sigma, (n_per_plane, 1))
        pts.append(corner + ab[:, :1] * edges[0] + ab[:, 1:] * edges[1] + noise * normals[k])
    lo, hi = np.array([-2.0, -4.0, -1.5]), np.array([8.0, 6.0, 3.5])
    pts.append(rng.uniform(lo, hi, (clutter, 3)))
    return np.vstack(pts), planes


def score_lines_f32(
    points: np.ndarray, lines: np.ndarray, threshold: float
) -> tuple[np.ndarray, np.ndarray]:
    """MSAC cost and inlier count of each line [p, u], emulating lidarcal's f32 arithmetic."""
    center = bbox_center(points[:, :3])
    x, y, z = ((points[:, i] - center[i]).astype(np.float32) for i in range(3))
    t2 = np.float32(threshold) * np.float32(threshold)
    costs, counts = [], []
    for line in lines:
        ux, uy, uz = (float(v) for v in line[3:])
        norm = np.sqrt(ux * ux + uy * uy + uz * uz)
        u = [np.float32(v / norm) for v in (ux, uy, uz)]
        c = [np.float32(float(line[i]) - center[i]) for i in range(3)]
        qx, qy, qz = x - c[0], y - c[1], z - c[2]
        along = u[0] * qx + u[1] * qy + u[2] * qz
        d2 = qx * qx + qy * qy + qz * qz - along * along
        inside = d2 < t2
        costs.append(float(np.sum(np.where(inside, d2, t2).astype(np.float64))))
        counts.append(int(inside.sum()))
    return np.array(costs), np.array(counts)


# --- Planar calibration -------------------------------------------------------------------


def plane_corner(planes: np.ndarray) -> np.ndarray:
    """The point where three planes [n, d] meet (eq. 3 of the planar seed)."""
    return np.linalg.solve(planes[:, :3], -planes[:, 3])


def planar_pipeline(
    planes_ref: np.ndarray,
    planes_tgt: np.ndarray,
    points_ref: list[np.ndarray],
    points_tgt: list[np.ndarray],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The planar method from given planes (normals toward each sensor) and their inlier points,
    with the target planes in any order. Returns (initial, refined, permutation): permutation[i]
    is the target plane matched to reference plane i."""
    import itertools

    best = None
    for perm in itertools.permutations(range(3)):
        tgt = planes_tgt[list(perm)]
        # Only correspondences that keep handedness are admissible.
        if np.sign(np.linalg.det(planes_ref[:, :3])) != np.sign(np.linalg.det(tgt[:, :3])):
            continue
        r = kabsch(planes_ref[:, :3], tgt[:, :3])
        score = np.sum((tgt[:, :3] @ r.T - planes_ref[:, :3]) ** 2)
        if best is None or score < best[0]:
            best = (score, perm, r)
    assert best is not None
    _, perm, r = best
    tgt = planes_tgt[list(perm)]
    initial = np.eye(4)
    initial[:3, :3] = r
    initial[:3, 3] = plane_corner(planes_ref) - r @ plane_corner(tgt)
    # Symmetric cost: target points on reference planes, reference points on target planes.
    groups_planes, groups_points, frames = [], [], []
    for i in range(3):
        groups_planes += [planes_ref[i], tgt[i]]
        groups_points += [points_tgt[perm[i]], points_ref[i]]
        frames += ["target", "reference"]
    refined, _ = solve_planes(np.array(groups_planes), groups_points, frames, initial)
    return initial, refined, np.array(perm)


def pose_graph_edge_error(a_from_b: np.ndarray, ref_a: np.ndarray, ref_b: np.ndarray) -> np.ndarray:
    """Tangent of the disagreement between a measured edge and the poses of its two nodes."""
    return se3_log(np.linalg.inv(a_from_b) @ np.linalg.inv(ref_a) @ ref_b)


def refine_pose_graph(
    poses: Sequence[np.ndarray],
    edges: Sequence[tuple[int, int, np.ndarray, np.ndarray]],
    iterations: int = 20,
) -> list[np.ndarray]:
    """Gauss-Newton on a pose graph with node 0 fixed; each edge ``(a, b, a_from_b, W)``
    contributes ``e^T W e``. Jacobians by forward differences on the left perturbation."""
    current = [np.array(p, dtype=np.float64) for p in poses]
    free = len(current) - 1
    if free <= 0 or not edges:
        return current
    h = 1e-6
    for _ in range(iterations):
        hessian = np.zeros((6 * free, 6 * free))
        gradient = np.zeros(6 * free)
        for a, b, z, w in edges:
            e0 = pose_graph_edge_error(z, current[a], current[b])
            jac = np.zeros((6, 6 * free))
            for node in {a, b} - {0}:
                for d in range(6):
                    delta = np.zeros(6)
                    delta[d] = h
                    moved = list(current)
                    moved[node] = se3_exp(delta) @ current[node]
                    e1 = pose_graph_edge_error(z, moved[a], moved[b])
                    jac[:, 6 * (node - 1) + d] = (e1 - e0) / h
            hessian += jac.T @ w @ jac
            gradient += jac.T @ w @ e0
        step = -np.linalg.solve(hessian + 1e-9 * np.eye(6 * free), gradient)
        for node in range(1, len(current)):
            current[node] = se3_exp(step[6 * (node - 1) : 6 * node]) @ current[node]
        if np.linalg.norm(step) < 1e-10:
            break
    return current
