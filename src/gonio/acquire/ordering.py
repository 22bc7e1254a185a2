"""Ordering configurations to minimize travel time.

All joints move at once, so a move costs its slowest joint under that joint's trapezoidal
profile (:meth:`gonio.rigs.config.JointConfig.move_time`). The order is an open travelling-
salesman path from the current pose: nearest neighbour, then 2-opt segment reversals until no
reversal helps (or a time budget runs out). Hand-written because the cost matrix is small and
dense (n <= a few thousand) and scipy has no TSP heuristic.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np

from gonio.rigs.config import JointConfig


def cost_matrix(poses_deg: np.ndarray, joints: Sequence[JointConfig]) -> np.ndarray:
    """Pairwise move times (s), shape (n, n), for poses (n, J) in degrees, columns = joints."""
    poses_deg = np.asarray(poses_deg, dtype=float)
    cost = np.zeros((len(poses_deg), len(poses_deg)))
    for k, j in enumerate(joints):
        d = poses_deg[:, None, k] - poses_deg[None, :, k]
        np.maximum(cost, j.move_time(d), out=cost)
    return cost


def move_times(start_deg, poses_deg, order, joints) -> np.ndarray:
    """Time (s) of each move when visiting ``poses_deg[order]`` starting from ``start_deg``."""
    seq = np.vstack([np.asarray(start_deg, dtype=float)[None], np.asarray(poses_deg)[order]])
    t = np.zeros(len(order))
    for k, j in enumerate(joints):
        t = np.maximum(t, j.move_time(np.diff(seq[:, k])))
    return t


def path_time(start_deg, poses_deg, order, joints) -> float:
    """Total motion time (s) of a visiting order."""
    return float(np.sum(move_times(start_deg, poses_deg, order, joints)))


def order_poses(
    start_deg, poses_deg, joints: Sequence[JointConfig], time_budget_s: float = 10.0
) -> np.ndarray:
    """Visiting order (indices into ``poses_deg``) minimizing total move time from ``start_deg``.

    Parameters
    ----------
    start_deg : (J,) current joint angles (deg), same column order as ``joints``.
    poses_deg : (n, J) target joint angles (deg).
    joints : the joints (their motion profiles).
    time_budget_s : wall-clock budget of the 2-opt improvement.
    """
    poses = np.asarray(poses_deg, dtype=float)
    n = len(poses)
    if n <= 1:
        return np.arange(n)
    allp = np.vstack([np.asarray(start_deg, dtype=float)[None], poses])
    d = cost_matrix(allp, joints)  # node 0 is the start
    # nearest neighbour
    path = [0]
    free = np.ones(n + 1, dtype=bool)
    free[0] = False
    cur = 0
    for _ in range(n):
        row = np.where(free, d[cur], np.inf)
        nxt = int(np.argmin(row))
        path.append(nxt)
        free[nxt] = False
        cur = nxt
    p = np.array(path)
    # 2-opt on the open path p[0..n] with p[0] fixed: reverse p[i..j], 1 <= i < j <= n
    deadline = time.monotonic() + time_budget_s
    improved = True
    while improved and time.monotonic() < deadline:
        improved = False
        for i in range(1, n):
            a = p[i - 1]
            b = p[i]
            js = np.arange(i + 1, n + 1)
            c = p[js]
            nxt = np.where(js + 1 <= n, p[np.minimum(js + 1, n)], -1)
            old = d[a, b] + np.where(nxt >= 0, d[c, np.maximum(nxt, 0)], 0.0)
            new = d[a, c] + np.where(nxt >= 0, d[b, np.maximum(nxt, 0)], 0.0)
            gain = old - new
            k = int(np.argmax(gain))
            if gain[k] > 1e-9:
                j = int(js[k])
                p[i : j + 1] = p[i : j + 1][::-1].copy()
                improved = True
            if time.monotonic() > deadline:
                break
    return p[1:] - 1


def choose_candidates(start_deg, candidates: Sequence[np.ndarray], order, joints) -> np.ndarray:
    """For a fixed visiting order, pick one pose per target minimizing total move time.

    ``candidates[i]`` is a (k_i, J) array of equivalent poses of target ``i`` (e.g. the two
    mirror solutions of the inverse kinematics). Exact by dynamic programming over the path
    (Viterbi): O(sum k_i k_{i+1}).
    """
    prev = np.asarray(start_deg, dtype=float)[None]
    acc = np.zeros(1)
    back = []
    for idx in order:
        cand = np.asarray(candidates[idx], dtype=float)
        step = cost_matrix_between(prev, cand, joints)  # (k_prev, k)
        tot = acc[:, None] + step
        arg = np.argmin(tot, axis=0)
        back.append(arg)
        acc = tot[arg, np.arange(cand.shape[0])]
        prev = cand
    choice = np.zeros(len(order), dtype=int)
    k = int(np.argmin(acc))
    for pos in range(len(order) - 1, -1, -1):
        choice[pos] = k
        k = int(back[pos][k])
    out = np.zeros(len(candidates), dtype=int)
    out[np.asarray(order)] = choice
    return out


def cost_matrix_between(a_deg: np.ndarray, b_deg: np.ndarray, joints) -> np.ndarray:
    """Move times (s) from each pose of ``a_deg`` (n, J) to each of ``b_deg`` (m, J)."""
    cost = np.zeros((len(a_deg), len(b_deg)))
    for k, j in enumerate(joints):
        np.maximum(cost, j.move_time(a_deg[:, None, k] - b_deg[None, :, k]), out=cost)
    return cost


def plan_route(
    start_deg,
    candidates: Sequence[np.ndarray],
    joints,
    time_budget_s: float = 10.0,
    rounds: int = 3,
) -> tuple[np.ndarray, np.ndarray]:
    """Order targets and choose among their equivalent poses; returns (order, choice).

    Alternates :func:`order_poses` (nearest neighbour + 2-opt on the chosen poses) and
    :func:`choose_candidates` (exact pose choice for that order) until neither improves.
    """
    n = len(candidates)
    if n == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    start = np.asarray(start_deg, dtype=float)
    choice = np.array(
        [
            int(np.argmin(cost_matrix_between(start[None], np.asarray(c), joints)[0]))
            for c in candidates
        ]
    )
    best = (np.inf, None, None)
    deadline = time.monotonic() + time_budget_s
    for _ in range(rounds):
        poses = np.array([candidates[i][choice[i]] for i in range(n)])
        order = order_poses(start, poses, joints, max(0.1, deadline - time.monotonic()))
        choice = choose_candidates(start, candidates, order, joints)
        poses = np.array([candidates[i][choice[i]] for i in range(n)])
        total = path_time(start, poses, order, joints)
        if total >= best[0] - 1e-9:
            break
        best = (total, order.copy(), choice.copy())
        if time.monotonic() > deadline:
            break
    return best[1], best[2]
