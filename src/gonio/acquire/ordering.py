"""Ordering configurations to minimize travel time.

All joints move at once, so a move costs its slowest joint under that joint's trapezoidal
profile (:meth:`gonio.rigs.config.JointConfig.move_time`). The order is an open travelling-
salesman path from the current pose. Up to :data:`MATRIX_MAX_POSES` poses it is planned on the
full cost matrix: nearest neighbour, then 2-opt segment reversals until no reversal helps (or a
time budget runs out). Larger sets are planned on neighbour lists, in O(n k) memory:

* each pose keeps its ``k`` cheapest moves. A move's time grows with each joint's |delta|, so
  poses scaled by each joint's cruise speed and compared in the Chebyshev (max) norm rank moves
  nearly as the true cost does: the lists are the ``k`` cheapest by exact move time among the
  ``2 k`` Chebyshev-nearest poses of a k-d tree;
* nearest neighbour: the cheapest unvisited pose of the current pose's list, else of one row of
  move times computed on the fly over the unvisited poses;
* local search with don't-look bits: 2-opt (two edges exchanged, one segment reversed) and
  Or-opt (a segment of one to three poses moved elsewhere, either way round), each trying only
  new edges to a listed neighbour, until no move helps or the time budget runs out.

Hand-written because scipy has no TSP heuristic.
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Sequence

import numpy as np

from gonio.rigs.config import JointConfig

#: Largest pose count ordered on the full cost matrix; above it, on neighbour lists.
MATRIX_MAX_POSES = 1000
#: Neighbours kept per pose on the neighbour-list path.
NEIGHBOURS = 10
#: Rows of the cost matrix computed at a time (bounds the temporaries to this many rows).
_ROWS = 256


def cost_matrix(poses_deg: np.ndarray, joints: Sequence[JointConfig]) -> np.ndarray:
    """Pairwise move times (s), shape (n, n), for poses (n, J) in degrees, columns = joints."""
    poses_deg = np.asarray(poses_deg, dtype=float)
    n = len(poses_deg)
    cost = np.zeros((n, n))
    for r in range(0, n, _ROWS):
        rows = poses_deg[r : r + _ROWS]
        cost[r : r + _ROWS] = cost_matrix_between(rows, poses_deg, joints)
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
    start_deg,
    poses_deg,
    joints: Sequence[JointConfig],
    time_budget_s: float = 10.0,
    initial: np.ndarray | None = None,
    lists: bool | None = None,
) -> np.ndarray:
    """Visiting order (indices into ``poses_deg``) minimizing total move time from ``start_deg``.

    Up to :data:`MATRIX_MAX_POSES` poses: nearest neighbour and 2-opt on the full cost matrix.
    Above: on neighbour lists (:func:`neighbour_lists`, :func:`nearest_neighbour`,
    :func:`improve`), in O(n k) memory.

    Parameters
    ----------
    start_deg : (J,) current joint angles (deg), same column order as ``joints``.
    poses_deg : (n, J) target joint angles (deg).
    joints : the joints (their motion profiles).
    time_budget_s : wall-clock budget (s) of the improvement.
    initial : (n,) an order to improve instead of the nearest-neighbour one; used only on
        neighbour lists.
    lists : True: neighbour lists, False: the full matrix, None: by the number of poses.

    Returns
    -------
    (n,) a permutation of ``range(n)``.
    """
    poses = np.asarray(poses_deg, dtype=float)
    n = len(poses)
    if n <= 1:
        return np.arange(n)
    allp = np.vstack([np.asarray(start_deg, dtype=float)[None], poses])
    if n > MATRIX_MAX_POSES if lists is None else lists:
        deadline = time.monotonic() + time_budget_s
        return _order_by_lists(allp, joints, deadline, initial)[1:] - 1
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


def _padded_candidates(candidates: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Equivalent poses of every target in one array.

    Parameters
    ----------
    candidates : n arrays (k_i, J) of equivalent poses (deg), k_i >= 1.

    Returns
    -------
    poses : (n, K, J) with K = max k_i; rows past k_i repeat the target's first pose.
    valid : (n, K) bool, True for the first k_i rows of each target.
    """
    counts = np.array([len(c) for c in candidates])
    width = int(counts.max())
    valid = np.arange(width)[None, :] < counts[:, None]
    poses = np.stack(
        [np.asarray(c, dtype=float)[np.minimum(np.arange(width), len(c) - 1)] for c in candidates]
    )
    return poses, valid


def _steps(a: np.ndarray, b: np.ndarray, joints) -> np.ndarray:
    """Move times (s) between matched rows of poses, (m, K, J) x (m, L, J) -> (m, K, L)."""
    cost = np.zeros((a.shape[0], a.shape[1], b.shape[1]))
    for k, j in enumerate(joints):
        np.maximum(cost, j.move_time(a[:, :, None, k] - b[:, None, :, k]), out=cost)
    return cost


def choose_candidates(start_deg, candidates: Sequence[np.ndarray], order, joints) -> np.ndarray:
    """For a fixed visiting order, pick one pose per target minimizing total move time.

    ``candidates[i]`` is a (k_i, J) array of equivalent poses of target ``i`` (e.g. the two
    mirror solutions of the inverse kinematics). Exact by dynamic programming over the path
    (Viterbi): O(sum k_i k_{i+1}); the move times of every step are computed at once.

    Returns
    -------
    (n,) index into ``candidates[i]`` of the pose chosen for target ``i``.
    """
    order = np.asarray(order, dtype=int)
    if len(order) == 0:
        return np.zeros(len(candidates), dtype=int)
    poses, valid = _padded_candidates(candidates)
    seq, ok = poses[order], valid[order]
    start = np.asarray(start_deg, dtype=float)
    prev = np.concatenate([np.broadcast_to(start, (1, seq.shape[1], len(start))), seq[:-1]])
    prev_ok = np.concatenate([(np.arange(seq.shape[1]) == 0)[None], ok[:-1]])
    step = _steps(prev, seq, joints)  # (n, K_prev, K)
    step[~prev_ok[:, :, None] | ~ok[:, None, :]] = np.inf
    cols = np.arange(seq.shape[1])
    acc = np.zeros(seq.shape[1])
    back = np.zeros((len(order), seq.shape[1]), dtype=int)
    for pos in range(len(order)):
        tot = acc[:, None] + step[pos]
        back[pos] = np.argmin(tot, axis=0)
        acc = tot[back[pos], cols]
    choice = np.zeros(len(order), dtype=int)
    k = int(np.argmin(acc))
    for pos in range(len(order) - 1, -1, -1):
        choice[pos] = k
        k = int(back[pos][k])
    out = np.zeros(len(candidates), dtype=int)
    out[order] = choice
    return out


def cost_matrix_between(a_deg: np.ndarray, b_deg: np.ndarray, joints) -> np.ndarray:
    """Move times (s) from each pose of ``a_deg`` (n, J) to each of ``b_deg`` (m, J), (n, m)."""
    a_deg = np.asarray(a_deg, dtype=float)
    b_deg = np.asarray(b_deg, dtype=float)
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
    """Order targets and choose among their equivalent poses.

    Alternates :func:`order_poses` (on the chosen poses) and :func:`choose_candidates` (exact
    pose choice for that order) until neither improves. Above :data:`MATRIX_MAX_POSES` targets
    each round improves the previous round's order instead of starting afresh.

    Parameters
    ----------
    start_deg : (J,) current joint angles (deg), same column order as ``joints``.
    candidates : n arrays (k_i, J) of equivalent poses (deg) of each target.
    joints : the joints (their motion profiles).
    time_budget_s : wall-clock budget (s) of all rounds' improvement together.
    rounds : most alternations.

    Returns
    -------
    order : (n,) visiting order, a permutation of ``range(n)``.
    choice : (n,) index into ``candidates[i]`` of the pose chosen for target ``i``.
    """
    n = len(candidates)
    if n == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    start = np.asarray(start_deg, dtype=float)
    padded, valid = _padded_candidates(candidates)
    from_start = _steps(np.broadcast_to(start, (n, 1, len(start))), padded, joints)[:, 0]
    choice = np.argmin(np.where(valid, from_start, np.inf), axis=1)
    best = (np.inf, None, None)
    deadline = time.monotonic() + time_budget_s
    order = None
    for _ in range(rounds):
        poses = np.array([candidates[i][choice[i]] for i in range(n)])
        budget = max(0.1, deadline - time.monotonic())
        order = order_poses(start, poses, joints, budget, initial=order)
        choice = choose_candidates(start, candidates, order, joints)
        poses = np.array([candidates[i][choice[i]] for i in range(n)])
        total = path_time(start, poses, order, joints)
        if total >= best[0] - 1e-9:
            break
        best = (total, order.copy(), choice.copy())
        if time.monotonic() > deadline:
            break
    return best[1], best[2]


# --- many poses: neighbour lists ---------------------------------------------------------

#: Smallest improvement (s) a local-search move must bring.
_EPS = 1e-9
#: Longest segment an Or-opt move relocates.
_OR_MAX = 3


def _row_times(src: np.ndarray, dst: np.ndarray, joints: Sequence[JointConfig]) -> np.ndarray:
    """Move times (s) from one pose ``src`` (J,) to each of ``dst`` (m, J), shape (m,)."""
    t = np.zeros(len(dst))
    for k, j in enumerate(joints):
        np.maximum(t, j.move_time(dst[:, k] - src[k]), out=t)
    return t


def neighbour_lists(
    points_deg: np.ndarray, joints: Sequence[JointConfig], k: int = NEIGHBOURS
) -> tuple[np.ndarray, np.ndarray]:
    """Each pose's ``k`` cheapest moves to other poses.

    Parameters
    ----------
    points_deg : (n, J) joint angles (deg), columns in the order of ``joints``.
    joints : the joints (their motion profiles).
    k : neighbours kept per pose (fewer when there are fewer other poses).

    Returns
    -------
    idx : (n, k) int array, the neighbours of each pose, cheapest move first.
    cost : (n, k) float array, the matching move times (s).
    """
    from scipy.spatial import cKDTree  # here: `gonio plan` of a small plan never pays its import

    pts = np.asarray(points_deg, dtype=float)
    n = len(pts)
    k = min(k, n - 1)
    if k <= 0:
        return np.zeros((n, 0), dtype=np.intp), np.zeros((n, 0))
    speed = np.array([j.profile_velocity_deg_s for j in joints], dtype=float)
    q = min(2 * k + 1, n)
    _, cand = cKDTree(pts / speed).query(pts / speed, k=q, p=np.inf)
    cand = np.asarray(cand, dtype=np.intp).reshape(n, q)
    cost = np.zeros(cand.shape)
    for c, j in enumerate(joints):
        np.maximum(cost, j.move_time(pts[cand, c] - pts[:, None, c]), out=cost)
    cost[cand == np.arange(n)[:, None]] = np.inf  # a pose is not its own neighbour
    keep = np.argsort(cost, axis=1, kind="stable")[:, :k]
    return np.take_along_axis(cand, keep, 1), np.take_along_axis(cost, keep, 1)


class _Route:
    """An open path over ``n + 1`` nodes with node 0 fixed first; scalar move times."""

    def __init__(self, points: np.ndarray, joints: Sequence[JointConfig], path: np.ndarray):
        self.pts = points.tolist()
        self.prof = []  # per joint: v, a, ramp distance v^2 / a, ramp time v / a
        for j in joints:
            v, a = j.profile_velocity_deg_s, j.profile_acceleration_deg_s2
            self.prof.append((v, a, v * v / a, v / a))
        self.p = np.array(path, dtype=np.intp)
        self.last = len(self.p) - 1
        self.pos = np.empty_like(self.p)
        self.pos[self.p] = np.arange(len(self.p))

    def cost(self, u: int, w: int) -> float:
        """Move time (s) between nodes ``u`` and ``w`` (as :meth:`JointConfig.move_time`)."""
        t = 0.0
        for x, y, (v, a, ramp, ramp_t) in zip(self.pts[u], self.pts[w], self.prof, strict=True):
            d = abs(x - y)
            tc = d / v + ramp_t if d >= ramp else 2.0 * math.sqrt(d / a)
            if tc > t:
                t = tc
        return t

    def reverse(self, i: int, j: int) -> None:
        """Reverse the path between positions ``i`` and ``j`` inclusive (1 <= i <= j)."""
        self.p[i : j + 1] = self.p[i : j + 1][::-1].copy()
        self.pos[self.p[i : j + 1]] = np.arange(i, j + 1)

    def relocate(self, s: int, e: int, after: int, flip: bool) -> None:
        """Move positions ``s..e`` to just after node ``after`` (outside them), reversed if
        ``flip``."""
        seg = self.p[s : e + 1].copy()
        if flip:
            seg = seg[::-1]
        rest = np.concatenate([self.p[:s], self.p[e + 1 :]])
        at = int(self.pos[after]) + 1
        if at > s:
            at -= len(seg)
        self.p = np.concatenate([rest[:at], seg, rest[at:]])
        self.pos[self.p] = np.arange(len(self.p))


def _two_opt(r: _Route, a: int, nbrs, succ: bool) -> tuple[int, ...] | None:
    """Try 2-opt moves adding edge (a, c) for listed neighbours c; apply the first that helps.

    ``nbrs``: (neighbour, move time) pairs of ``a``, cheapest first. ``succ``: the edges removed
    leave ``a`` and ``c`` forward (else backward). Returns the nodes whose edges changed, or None.
    """
    i = int(r.pos[a])
    if succ:
        if i == r.last:
            return None
        b = int(r.p[i + 1])
    else:
        if i == 0:
            return None
        b = int(r.p[i - 1])
    d_ab = r.cost(a, b)
    for c, d_ac in nbrs:
        if d_ac >= d_ab - _EPS:
            break
        if c == b or (c == 0 and not succ):
            continue
        j = int(r.pos[c])
        if succ:
            if j == r.last:  # c last: (a, b) out, (a, c) in, b becomes last
                if d_ab - d_ac > _EPS:
                    r.reverse(i + 1, j)
                    return a, b, c
                continue
            d = int(r.p[j + 1])
            if r.cost(c, d) + d_ab - d_ac - r.cost(b, d) > _EPS:
                lo, hi = (i, j) if i < j else (j, i)
                r.reverse(lo + 1, hi)
                return a, b, c, d
        else:
            d = int(r.p[j - 1])
            if r.cost(d, c) + d_ab - d_ac - r.cost(b, d) > _EPS:
                lo, hi = (i, j) if i < j else (j, i)
                r.reverse(lo, hi - 1)
                return a, b, c, d
    return None


def _or_opt(r: _Route, a: int, nbr_of) -> tuple[int, ...] | None:
    """Try moving a segment that starts at ``a`` (1 to 3 poses, forward) next to a listed
    neighbour of either of its ends; apply the first move that helps. ``nbr_of(u)``: the
    (neighbour, move time) pairs of node ``u``, cheapest first. Returns the nodes whose edges
    changed, or None."""
    s = int(r.pos[a])
    if s == 0:
        return None
    prev = int(r.p[s - 1])
    for e in range(s, min(s + _OR_MAX, r.last + 1)):
        last = int(r.p[e])
        seg = set(r.p[s : e + 1].tolist())
        nxt = int(r.p[e + 1]) if e < r.last else -1
        gain = r.cost(prev, a)
        if nxt >= 0:
            gain += r.cost(last, nxt) - r.cost(prev, nxt)
        for x, y in ((a, last), (last, a)):  # x joins the neighbour c, y the far side
            for c, d_cx in nbr_of(x):
                if d_cx >= gain - _EPS:
                    break
                if c in seg:
                    continue
                jc = int(r.pos[c])
                for after_c in (True, False):
                    if after_c:
                        c2 = int(r.p[jc + 1]) if jc < r.last else -1
                    else:
                        if c == 0:
                            continue
                        c2 = int(r.p[jc - 1])
                    if c2 in seg:
                        continue
                    add = d_cx + (r.cost(y, c2) - r.cost(c, c2) if c2 >= 0 else 0.0)
                    if gain - add > _EPS:
                        if after_c:  # c, x .. y, c2
                            r.relocate(s, e, c, flip=x != a)
                        else:  # c2, y .. x, c
                            r.relocate(s, e, c2, flip=x == a)
                        return prev, a, last, nxt, c, c2
    return None


def improve(
    points: np.ndarray,
    joints: Sequence[JointConfig],
    path: np.ndarray,
    nbr_idx: np.ndarray,
    nbr_cost: np.ndarray,
    deadline: float,
) -> np.ndarray:
    """2-opt and Or-opt on neighbour lists with don't-look bits.

    Parameters
    ----------
    points : (n + 1, J) joint angles (deg); node 0 is the fixed start.
    joints : the joints (their motion profiles).
    path : (n + 1,) a visiting order of all nodes, ``path[0] == 0``.
    nbr_idx, nbr_cost : (n + 1, k) from :func:`neighbour_lists`.
    deadline : :func:`time.monotonic` time to stop at.

    Returns
    -------
    (n + 1,) the improved path, still starting at node 0.
    """
    r = _Route(points, joints, path)
    idx, cost = nbr_idx.tolist(), nbr_cost.tolist()

    def nbrs(u: int):
        """(neighbour, move time) pairs of node ``u``, cheapest first."""
        return zip(idx[u], cost[u], strict=True)

    queue = deque(r.p.tolist())
    queued = np.ones(len(r.p), dtype=bool)
    steps = 0
    while queue:
        steps += 1
        if steps % 64 == 0 and time.monotonic() > deadline:
            break
        a = queue.popleft()
        queued[a] = False
        changed = (
            _two_opt(r, a, nbrs(a), True) or _two_opt(r, a, nbrs(a), False) or _or_opt(r, a, nbrs)
        )
        if changed:
            for u in changed:
                if u >= 0 and not queued[u]:
                    queued[u] = True
                    queue.append(u)
            if not queued[a]:
                queued[a] = True
                queue.append(a)
    return r.p


def nearest_neighbour(
    points: np.ndarray, joints: Sequence[JointConfig], nbr_idx: np.ndarray
) -> np.ndarray:
    """Nearest-neighbour path from node 0 through all of ``points`` (n + 1, J), by move time.

    The next node is the first unvisited one of the current node's neighbour list (cheapest
    first); when all of them are visited, one row of move times to the unvisited nodes is
    computed. Returns the (n + 1,) path starting at 0.
    """
    m = len(points)
    visited = np.zeros(m, dtype=bool)
    visited[0] = True
    free = np.arange(1, m)
    lists = nbr_idx.tolist()
    path = np.zeros(m, dtype=np.intp)
    cur = 0
    for step in range(1, m):
        nxt = next((c for c in lists[cur] if not visited[c]), -1)
        if nxt < 0:
            free = free[~visited[free]]
            nxt = int(free[np.argmin(_row_times(points[cur], points[free], joints))])
        path[step] = nxt
        visited[nxt] = True
        cur = nxt
    return path


def _order_by_lists(
    points: np.ndarray, joints: Sequence[JointConfig], deadline: float, initial
) -> np.ndarray:
    """Open path from node 0 through ``points`` (n + 1, J): nearest neighbour (or ``initial``,
    (n,) indices of ``points[1:]``) improved by :func:`improve` until ``deadline``."""
    idx, cost = neighbour_lists(points, joints)
    if initial is None:
        path = nearest_neighbour(points, joints, idx)
    else:
        path = np.concatenate([[0], np.asarray(initial, dtype=np.intp) + 1])
    return improve(points, joints, path, idx, cost, deadline)
