"""Forward and inverse kinematics of the 4-axis rig (two coaxial arms, tilt stage, turntable).

Frames
------
World: the light and camera arms rotate about the world z axis, so the light and the camera
always lie in the world xy plane ("measurement plane"), at arm angles ``a_l`` and ``a_c``
measured from +x towards +y: ``l = (cos a_l, sin a_l, 0)``.

Sample: the sample sits at the origin. Its local frame (x tangent, y bitangent, z normal,
the convention of :mod:`gonio.brdf.frames`) maps to world by

    M(tilt, rot) = R_y(tilt) @ B @ R_z(rot),   B = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]

i.e. at tilt = rot = 0 the normal points along +x (towards arm angle 0), the tangent along +y
and the bitangent along +z; ``rot`` turns the sample about its own normal and ``tilt`` turns
the stage about world y, lifting the normal out of the measurement plane. Directions in the
sample frame are ``wi = M^T l`` and ``wo = M^T c``.

All angles here are radians; joint angles come from the rig file's joint limits (degrees) and
are converted at this boundary.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gonio.errors import PlanError
from gonio.rigs.config import RigConfig

_B = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def sample_to_world(tilt, rot) -> np.ndarray:
    """Rotation matrices ``M`` (..., 3, 3) taking sample-frame vectors to world (radians in)."""
    tilt = np.asarray(tilt, dtype=float)
    rot = np.asarray(rot, dtype=float)
    ct, st = np.cos(tilt), np.sin(tilt)
    cr, sr = np.cos(rot), np.sin(rot)
    z, o = np.zeros_like(ct + cr), np.ones_like(ct + cr)
    ry = np.stack(
        [np.stack([ct, z, st], -1), np.stack([z, o, z], -1), np.stack([-st, z, ct], -1)], -2
    )
    rz = np.stack(
        [np.stack([cr, -sr, z], -1), np.stack([sr, cr, z], -1), np.stack([z, z, o], -1)], -2
    )
    return ry @ _B @ rz


def forward(a_light, a_camera, tilt, rot) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (radians, broadcastable) -> (wi, wo): unit vectors (..., 3), sample frame."""
    m = sample_to_world(tilt, rot)
    a_light = np.asarray(a_light, dtype=float)
    a_camera = np.asarray(a_camera, dtype=float)
    l = np.stack([np.cos(a_light), np.sin(a_light), np.zeros_like(a_light)], -1)
    c = np.stack([np.cos(a_camera), np.sin(a_camera), np.zeros_like(a_camera)], -1)
    mt = np.swapaxes(m, -1, -2)
    wi = np.einsum("...ij,...j->...i", mt, l)
    wo = np.einsum("...ij,...j->...i", mt, c)
    return wi, wo


def spherical(w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(theta, phi) in radians of unit vectors (..., 3); phi in [0, 2 pi)."""
    w = np.asarray(w, dtype=float)
    theta = np.arccos(np.clip(w[..., 2], -1.0, 1.0))
    phi = np.mod(np.arctan2(w[..., 1], w[..., 0]), 2 * np.pi)
    return theta, phi


def direction(theta, phi) -> np.ndarray:
    """Unit vector(s) (..., 3) from polar ``theta`` and azimuth ``phi`` (radians)."""
    theta = np.asarray(theta, dtype=float)
    phi = np.asarray(phi, dtype=float)
    st = np.sin(theta)
    return np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], -1)


@dataclass(frozen=True)
class Pose:
    """A rig pose: joint angles in radians keyed by the layout roles."""

    light: float
    camera: float
    tilt: float
    rot: float

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (self.light, self.camera, self.tilt, self.rot)


class Kinematics:
    """Kinematics of one rig: role <-> joint mapping, limits and safety checks.

    Parameters
    ----------
    rig : RigConfig
        The rig file (layout, joint limits, safety margins).
    """

    ROLES = ("light", "camera", "tilt", "rot")

    def __init__(self, rig: RigConfig) -> None:
        self.rig = rig
        lay = rig.layout
        self.joint_names = {
            "light": lay.light,
            "camera": lay.camera,
            "tilt": lay.tilt,
            "rot": lay.rotation,
        }
        self._limits = {}
        for role, name in self.joint_names.items():
            j = rig.joint(name)
            self._limits[role] = (math.radians(j.min_deg), math.radians(j.max_deg))
        self.min_sep = math.radians(rig.safety.min_light_camera_deg)
        self.arms_can_pass = rig.safety.arms_can_pass
        park_l = rig.park_deg.get(lay.light, 0.0)
        park_c = rig.park_deg.get(lay.camera, 0.0)
        self._arm_order = 1.0 if park_l >= park_c else -1.0
        self.max_theta = math.radians(rig.safety.max_theta_deg)
        self._keepout = [
            (
                role,
                math.radians(k.min_deg),
                math.radians(k.max_deg),
                k.reason,
                k.joint,
                math.radians(rig.park_deg.get(k.joint, rig.joint(k.joint).zero_offset_deg)),
            )
            for k in rig.safety.keepout
            for role, name in self.joint_names.items()
            if name == k.joint
        ]

    # --- conversions ----------------------------------------------------------------------------
    def pose_to_joints_deg(self, pose: Pose) -> dict[str, float]:
        """Pose (radians, by role) -> joint angles in degrees keyed by joint name."""
        return {
            self.joint_names[r]: math.degrees(v)
            for r, v in zip(self.ROLES, pose.as_tuple(), strict=True)
        }

    def joints_deg_to_pose(self, joints: dict[str, float]) -> Pose:
        """Joint angles (deg, by joint name) -> Pose (radians)."""
        return Pose(*(math.radians(joints[self.joint_names[r]]) for r in self.ROLES))

    def forward(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """(wi, wo) in the sample frame for a pose."""
        return forward(pose.light, pose.camera, pose.tilt, pose.rot)

    # --- safety -------------------------------------------------------------------------------
    def refusal(self, pose: Pose) -> str | None:
        """Why the rig must not go to ``pose`` (None if it may)."""
        for role, v in zip(self.ROLES, pose.as_tuple(), strict=True):
            lo, hi = self._limits[role]
            if not lo - 1e-9 <= v <= hi + 1e-9:
                return (
                    f"joint {self.joint_names[role]} at {math.degrees(v):.2f} deg is outside"
                    f" its limits [{math.degrees(lo):.1f}, {math.degrees(hi):.1f}]"
                )
        # every comparison below is written so that NaN refuses (a NaN compares false)
        for role, lo, hi, reason, name, park in self._keepout:
            v = getattr(pose, role)
            if not (v < lo or v > hi):
                return (
                    f"joint {name} at {math.degrees(v):.2f} deg is in a keep-out sector ({reason})"
                )
            # every move is monotone in each joint, so a sector may never be crossed either:
            # the joint stays on the park pose's side of it
            if not ((v > hi and park > hi) or (v < lo and park < lo)):
                return (
                    f"joint {name} at {math.degrees(v):.2f} deg is across the keep-out sector"
                    f" [{math.degrees(lo):.1f}, {math.degrees(hi):.1f}] from its park angle"
                    f" ({reason})"
                )
        if not self.arms_can_pass and not (pose.light - pose.camera) * self._arm_order >= 0:
            return (
                "light and camera arms would have to pass each other (they keep their park"
                " order; safety.arms_can_pass = false)"
            )
        sep = abs(math.remainder(pose.light - pose.camera, 2 * math.pi))
        if not sep >= self.min_sep - 1e-12:
            return (
                f"light and camera arms {math.degrees(sep):.2f} deg apart"
                f" (< min_light_camera_deg {math.degrees(self.min_sep):.1f}: occlusion/collision)"
            )
        wi, wo = self.forward(pose)
        for name, w in (("light", wi), ("camera", wo)):
            z = float(w[2])
            th = math.acos(max(-1.0, min(1.0, z))) if z == z else math.nan
            if not th <= self.max_theta + 1e-9:
                where = "below the sample horizon" if th > math.pi / 2 else "too grazing"
                return (
                    f"{name} at theta {math.degrees(th):.2f} deg is {where}"
                    f" (max_theta_deg {math.degrees(self.max_theta):.1f})"
                )
        return None

    # --- inverse ------------------------------------------------------------------------------
    def candidates(self, wi, wo, isotropic: bool = False, rot_hint: float = 0.0) -> list[Pose]:
        """Every pose (within +-2 pi wraps) whose forward kinematics gives (wi, wo).

        With ``isotropic`` the azimuth of the pair is free (isotropic sample): the turntable is
        held at ``rot_hint`` and the pair rotated about the normal to suit.
        """
        wi = np.asarray(wi, dtype=float)
        wo = np.asarray(wo, dtype=float)
        wi = wi / np.linalg.norm(wi)
        wo = wo / np.linalg.norm(wo)
        m = np.cross(wi, wo)
        nm = np.linalg.norm(m)
        if nm < 1e-9:
            # light and camera coincide (or are opposite): no plane is defined; any refusal
            # from the separation check applies, so build one representative pose.
            t = np.array([1.0, 0.0, 0.0]) if abs(wi[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
            m = np.cross(wi, t)
            nm = np.linalg.norm(m)
        m = m / nm
        out: list[Pose] = []
        for s in (1.0, -1.0):
            ms = s * m
            h = math.hypot(ms[0], ms[1])
            rot = math.atan2(ms[0], ms[1]) if h > 1e-12 else 0.0
            tilt = math.atan2(-ms[2], h)
            if isotropic:
                # rotate the pair about the normal so that the turntable sits at rot_hint
                beta = rot_hint - rot
                cb, sb = math.cos(beta), math.sin(beta)
                rz = np.array([[cb, -sb, 0.0], [sb, cb, 0.0], [0.0, 0.0, 1.0]])
                wi_s, wo_s = rz.T @ wi, rz.T @ wo
                rot = rot_hint
            else:
                wi_s, wo_s = wi, wo
            mm = sample_to_world(tilt, rot)
            lw, cw = mm @ wi_s, mm @ wo_s
            a_l = math.atan2(lw[1], lw[0])
            a_c = math.atan2(cw[1], cw[0])
            for dl in (0.0, 2 * math.pi, -2 * math.pi):
                for dc in (0.0, 2 * math.pi, -2 * math.pi):
                    for dr in (0.0,) if isotropic else (0.0, 2 * math.pi, -2 * math.pi):
                        out.append(Pose(a_l + dl, a_c + dc, tilt, rot + dr))
        return out

    def inverse(
        self, wi, wo, isotropic: bool = False, near: Pose | None = None
    ) -> tuple[Pose | None, str | None]:
        """A safe pose reaching (wi, wo), the one closest to ``near``; else (None, reason).

        Directions are unit vectors (3,) in the sample frame. Returns the refusal of the best
        candidate when none is allowed.
        """
        rot_hint = near.rot if (near is not None and isotropic) else 0.0
        cands = self.candidates(wi, wo, isotropic, rot_hint)
        ok = []
        reasons = []
        for c in cands:
            why = self.refusal(c)
            if why is None:
                ok.append(c)
            else:
                reasons.append(why)
        if not ok:
            # the most fundamental reason first: geometry the rig can never realize, then
            # safety margins, then the side rules, then plain joint limits
            rank = ("horizon", "grazing", "min_light_camera_deg", "keep-out", "pass each other")

            def key(r: str) -> int:
                return next((i for i, k in enumerate(rank) if k in r), len(rank))

            return None, min(reasons, key=key)
        if near is None:
            near = Pose(0.0, 0.0, 0.0, 0.0)
        ref = np.array(near.as_tuple())
        best = min(ok, key=lambda c: float(np.max(np.abs(np.array(c.as_tuple()) - ref))))
        return best, None

    def require(self, wi, wo, isotropic: bool = False, near: Pose | None = None) -> Pose:
        """Like :meth:`inverse` but raises PlanError with the reason."""
        pose, why = self.inverse(wi, wo, isotropic, near)
        if pose is None:
            th_i, ph_i = spherical(np.asarray(wi))
            th_o, ph_o = spherical(np.asarray(wo))
            raise PlanError(
                f"pose theta_i={math.degrees(th_i):.1f} phi_i={math.degrees(ph_i):.1f}"
                f" theta_o={math.degrees(th_o):.1f} phi_o={math.degrees(ph_o):.1f} deg"
                f" refused: {why}"
            )
        return pose
