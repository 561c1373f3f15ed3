"""Pictures (PNG). Importing this package does not import matplotlib; drawing functions do."""

from graspnet_torch.viz.plots import plot_learning_curves, plot_noise_study
from graspnet_torch.viz.robot import Panel, render_robot

__all__ = ["Panel", "plot_learning_curves", "plot_noise_study", "render_robot"]
