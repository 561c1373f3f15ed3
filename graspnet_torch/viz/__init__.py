"""Pictures (PNG). Importing this package does not import matplotlib; drawing functions do."""

from graspnet_torch.viz.robot import Panel, render_robot

__all__ = ["Panel", "render_robot"]
