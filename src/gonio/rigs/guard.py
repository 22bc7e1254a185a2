"""The last-moment safety check of every Goal Position before its packet is written.

Plans are checked by the kinematics (:meth:`gonio.rigs.kinematics.Kinematics.refusal`) and every
pose again by :meth:`gonio.rigs.dynamixel.ServoChain.check_limits`; this is the third and last
check, on the raw ticks that are about to go on the wire, so that no bug upstream and no bad
number in a rig file can send a servo beyond its limits or into a keep-out sector. Every
comparison is written ``not (lo <= x <= hi)`` so that a NaN refuses.

The check is deliberately independent of the code it guards: it converts the ticks back to joint
angles and compares them with the rig file's numbers. A goal may lie up to half a servo tick
beyond a limit or inside a sector edge: the rounding of an allowed angle to the nearest tick.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from gonio.errors import PlanError
from gonio.rigs import control_table as ct
from gonio.rigs.config import JointConfig, RigConfig


class GoalGuard:
    """Refuses (PlanError) any goal a rig must never receive.

    Parameters
    ----------
    rig : RigConfig
        The validated rig file: joint limits, keep-out sectors and their home side, the arms'
        minimum separation and order.
    """

    def __init__(self, rig: RigConfig) -> None:
        self.rig = rig
        self._by_id: dict[int, JointConfig] = {j.id: j for j in rig.joints}
        self._range = {
            j.id: ct.POSITION_RANGE[ct.OPERATING_MODES[j.operating_mode]] for j in rig.joints
        }
        self._keepouts = {
            j.id: [
                (k, rig.park_deg.get(j.name, j.zero_offset_deg))
                for k in rig.safety.keepout
                if k.joint == j.name
            ]
            for j in rig.joints
        }
        lay = rig.layout
        self._light = rig.joint(lay.light)
        self._camera = rig.joint(lay.camera)
        park_l = rig.park_deg.get(lay.light, 0.0)
        park_c = rig.park_deg.get(lay.camera, 0.0)
        self._order = 1.0 if park_l >= park_c else -1.0

    @staticmethod
    def _slack(j: JointConfig) -> float:
        """Half a servo tick in joint degrees, plus rounding of the float arithmetic."""
        return 180.0 / ct.TICKS_PER_REV / j.gear_ratio + 1e-9

    def check_goal(self, servo_id: int, ticks: int) -> float:
        """Check one goal; return its joint angle (deg). PlanError when refused."""
        j = self._by_id.get(servo_id)
        if j is None:
            raise PlanError(f"goal for servo {servo_id}, which is no joint of rig {self.rig.name}")
        lo, hi = self._range[servo_id]
        if not (isinstance(ticks, int) and lo <= ticks <= hi):
            raise PlanError(f"joint {j.name}: goal tick {ticks!r} outside the register {lo}..{hi}")
        a = j.from_ticks(ticks)
        s = self._slack(j)
        if not (j.min_deg - s <= a <= j.max_deg + s):
            raise PlanError(
                f"joint {j.name}: goal {a:.3f} deg beyond its limits [{j.min_deg}, {j.max_deg}]"
            )
        for k, home in self._keepouts[servo_id]:
            below = a < k.min_deg + s and home < k.min_deg
            above = a > k.max_deg - s and home > k.max_deg
            if not (below or above):
                raise PlanError(
                    f"joint {j.name}: goal {a:.3f} deg in or across the keep-out sector"
                    f" [{k.min_deg}, {k.max_deg}] ({k.reason})"
                )
        return a

    def check(
        self, goals: Mapping[int, int], present_deg: Mapping[str, float] | None = None
    ) -> dict[str, float]:
        """Check every goal, and the arms of a pose naming both; return the angles (deg).

        The light and camera arms must keep their park order (unless ``arms_can_pass``) and
        stay ``min_light_camera_deg`` apart, except that a move which does not bring them
        closer than they are now (``present_deg``) is allowed, so that a rig powered on in a
        bad pose can always be parked.
        """
        angles = {self._by_id[i].name: self.check_goal(i, t) for i, t in goals.items()}
        ln, cn = self._light.name, self._camera.name
        if ln in angles and cn in angles:
            d = (angles[ln] - angles[cn]) * self._order
            s = self._slack(self._light) + self._slack(self._camera)
            if not self.rig.safety.arms_can_pass and not d >= -s:
                raise PlanError("goal would make the light and camera arms pass each other")
            sep = abs(math.remainder(angles[ln] - angles[cn], 360.0))
            floor = self.rig.safety.min_light_camera_deg
            if present_deg is not None and ln in present_deg and cn in present_deg:
                now = abs(math.remainder(present_deg[ln] - present_deg[cn], 360.0))
                floor = min(floor, now)
            if not sep >= floor - s:
                raise PlanError(
                    f"goal puts the light and camera arms {sep:.3f} deg apart"
                    f" (< min_light_camera_deg {self.rig.safety.min_light_camera_deg})"
                )
        return angles
