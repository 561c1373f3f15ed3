"""The robot kinds, one module each, each with its row of :data:`graspnet_torch.robot.kinds.KINDS`.

============  ==================================================================================
``hand``      a free palm with fingers: the configuration network places the palm, the FCNN the fingers
``arm_hand``  fingers on a body chain (an arm): the arm's joints, the FCNN places the fingers
``gripper``   a body chain with two marked gripper points (MANUS on its mobile base), no fingers
============  ==================================================================================

Importing this package registers the rows; :mod:`graspnet_torch` imports it, so every use of the
package finds them. A new kind: one module here that makes its :class:`RobotKind` row (naming the
parts it adds in their layers: its environment, head, random problems) and registers it, plus its
import below.
"""

from graspnet_torch.robot.kinds import KINDS, RobotKind, robot_kind
from graspnet_torch.solver.kinds.arm_hand import ARM_HAND
from graspnet_torch.solver.kinds.gripper import GRIPPER
from graspnet_torch.solver.kinds.hand import HAND

__all__ = ["ARM_HAND", "GRIPPER", "HAND", "KINDS", "RobotKind", "robot_kind"]
