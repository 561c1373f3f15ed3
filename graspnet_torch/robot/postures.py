"""Moved (issue 39, the layers): :func:`trial_posture` is the solver's
(:mod:`graspnet_torch.solver.postures`), :func:`reference_posture` the problem's
(:mod:`graspnet_torch.tasks.reference`); the robot's home posture is :meth:`Robot.home_posture`.

Kept only until ``solver/api.py``, ``solver/session.py`` and ``solver/environment.py`` import them
from their modules; then this file and its ``ignore_imports`` lines in pyproject.toml go.
"""

from __future__ import annotations

from graspnet_torch.solver.postures import trial_posture
from graspnet_torch.tasks.reference import reference_posture

__all__ = ["reference_posture", "trial_posture"]
