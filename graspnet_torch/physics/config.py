"""Settings of the physics check of a grasp (:class:`PhysicsCfg`): the pinned protocol.

The protocol is DexGraspBench's: friction 0.6 tangential / 0.02 torsional, elliptic cones, object
100 g, timestep 4 ms, an external force of the object's weight along +-x, +-y, +-z in turn for 2 s
each; holds when the object moves less than 5 cm and turns less than 15 degrees. Pinned here beside
it (the choices DexGraspBench leaves to its models, or that this package adds): gravity off
throughout (the external force replaces it), each push from the same settled state, a settle phase
of 0.5 s first in which the fingers are commanded to the squeeze posture, and the finger drives
(position actuators of gain ``kp``, joint damping and armature, a force limit).
"""

from __future__ import annotations

from dataclasses import dataclass

from graspnet_torch.settings import setting

__all__ = ["DIRECTIONS", "PhysicsCfg"]

DIRECTIONS = ("+x", "-x", "+y", "-y", "+z", "-z")  # the pushes, in the world frame, in this order


@dataclass(frozen=True)
class PhysicsCfg:
    """The physics check's protocol and model settings (:func:`~graspnet_torch.physics.simulate_grasp`).

    Attributes:
        friction: tangential friction coefficient of every contact (DexGraspBench: 0.6).
        torsional_friction: torsional friction (m; DexGraspBench: 0.02). Rolling friction is off
            (contacts of dimension 4: tangential and torsional).
        object_mass_kg: the object's mass (DexGraspBench: 0.1); its inertia follows from its shape
            (uniform density).
        timestep_s: the simulation step (DexGraspBench: 0.004), implicitfast integrator, elliptic
            friction cones.
        push_s: how long each external force acts (DexGraspBench: 2 s).
        force_scale: the external force's size in object weights (m g; DexGraspBench: 1), applied
            at the object's centre of mass.
        max_shift_mm: a push holds when the object's centre of mass ends it less than this far
            from where the settle left it (DexGraspBench: 50) ...
        max_turn_deg: ... and turned less than this (DexGraspBench: 15).
        settle_s: the settle phase before the pushes: no external force, the fingers commanded from
            the grasp posture to the squeeze posture.
        settle_max_shift_mm: the report's ``moved_while_settling`` is true when the settle moved the
            object's centre of mass more than this.
        gravity: gravity (-z, 9.81 m/s^2) on the object and the robot during the settle and the
            pushes. Off by default: the protocol's external force replaces it.
        kp: position gain of the revolute joints' actuators (N m/rad): a human-size finger
            commanded 5 mm past a contact presses it with a few newtons.
        kp_prismatic: position gain of the prismatic joints' actuators (N/m).
        damping: joint damping (N m s/rad, N s/m) of the driven joints.
        armature: rotor inertia added to the driven joints (kg m^2, kg): keeps the stiff drives
            stable at the 4 ms step.
        max_effort: the actuators' force limit (N m, N); a URDF ``effort`` below it limits instead.
        until_failure: stop at the first push that fails; the pushes after it are not run (nor
            reported). Whether a grasp holds every push is decided the same, sooner where it does
            not (each push starts from the same settled state): what a search that keeps only grasps
            holding every push needs. Off: every push is run and reported.
    """

    friction: float = setting(0.6, lo=0.0, hi=10.0)
    torsional_friction: float = setting(0.02, lo=0.0, hi=1.0)
    object_mass_kg: float = setting(0.1, lo=0.0, lo_open=True, hi=1000.0)
    timestep_s: float = setting(0.004, lo=1e-5, hi=0.05)
    push_s: float = setting(2.0, lo=0.0, lo_open=True, hi=60.0)
    force_scale: float = setting(1.0, lo=0.0, hi=100.0)
    max_shift_mm: float = setting(50.0, lo=0.0, lo_open=True, hi=10_000.0)
    max_turn_deg: float = setting(15.0, lo=0.0, lo_open=True, hi=180.0)
    settle_s: float = setting(0.5, lo=0.0, hi=60.0)
    settle_max_shift_mm: float = setting(5.0, lo=0.0, hi=10_000.0)
    gravity: bool = setting(False)
    kp: float = setting(10.0, lo=0.0, lo_open=True, hi=1e6)
    kp_prismatic: float = setting(2000.0, lo=0.0, lo_open=True, hi=1e8)
    damping: float = setting(0.1, lo=0.0, hi=1e6)
    armature: float = setting(0.001, lo=0.0, hi=1e3)
    max_effort: float = setting(10.0, lo=0.0, lo_open=True, hi=1e6)
    until_failure: bool = setting(False)

    def protocol(self) -> dict:
        """The report's ``protocol``: what a reader needs to compare two checks."""
        return {"friction": [self.friction, self.torsional_friction], "object_mass_kg": self.object_mass_kg,
                "duration_s": self.push_s, "max_shift_mm": self.max_shift_mm, "max_turn_deg": self.max_turn_deg,
                "timestep_s": self.timestep_s}
