"""Plots of learning curves (PNG), like the paper's Fig. 3 and Fig. 8."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from graspnet_torch.viz.robot import save_figure

__all__ = ["plot_learning_curves", "plot_noise_study"]


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def plot_learning_curves(history: Mapping[str, np.ndarray], path: str | Path, title: str = "",
                         highlight: int | None = None) -> Path:
    """Reinforcement, total error, expected reinforcement and sigma per iteration.

    history: arrays (K, T) under 'reinforcement', 'total' (m) and, where the solver has them,
    'expected', 'sigma', 'step_size' (CMA-ES) and 'collisions' (a panel as the paper's Fig. 9);
    'iteration' (K,): the x values when the rows are not consecutive iterations (CMA-ES: one row
    per generation). Every trial is a thin line, ``highlight`` (a trial index) a bold one.
    """
    plt = _plt()
    panels = [("reinforcement", "a/ reinforcement r", None), ("total", "b/ total error E (m)", "log"),
              ("expected", "c/ expected reinforcement r_hat (mean over SRV units)", None),
              ("sigma", "d/ standard deviation sigma (mean over SRV units)", None),
              ("step_size", "c/ CMA-ES step size (normalised units)", "log")]
    if "collisions" in history:
        panels.append(("collisions", "e/ collisions (the loop's count)", None))
    panels = [p for p in panels if p[0] in history]  # CMA-ES and DLS have no r_hat (CMA-ES: its step size)
    rows = (len(panels) + 1) // 2
    fig, axes = plt.subplots(rows, 2, figsize=(10, 3.25 * rows), dpi=110, sharex=True, squeeze=False)
    if len(panels) % 2:
        axes.ravel()[-1].set_visible(False)
    for ax, (key, label, scale) in zip(axes.ravel(), panels, strict=False):
        data = np.asarray(history[key])
        x = np.asarray(history["iteration"]) if "iteration" in history else np.arange(1, data.shape[0] + 1)
        ax.plot(x, data, color="tab:blue", alpha=0.25, linewidth=0.7)
        if highlight is not None:
            ax.plot(x, data[:, highlight], color="tab:red", linewidth=1.4, label=f"trial {highlight}")
            ax.legend(fontsize=7, loc="best")
        if scale:
            ax.set_yscale(scale)
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("iteration")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def plot_noise_study(curves: Mapping[float, Mapping[str, np.ndarray]], path: str | Path, title: str = "") -> Path:
    """Fig. 3: reinforcement (a) and deterministic error (b) per iteration for each noise level.

    curves: sigma_n -> {'reinforcement': (K,), 'total': (K,)} (e.g. medians over trials).
    """
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=110)
    colors = plt.cm.viridis(np.linspace(0, 0.9, len(curves)))
    for color, (sigma, c) in zip(colors, sorted(curves.items()), strict=True):
        x = np.arange(1, len(c["reinforcement"]) + 1)
        axes[0].plot(x, c["reinforcement"], color=color, linewidth=0.8, label=f"sigma_n = {sigma:g}")
        axes[1].plot(x, c["total"], color=color, linewidth=1.0, label=f"sigma_n = {sigma:g}")
    axes[0].set_title("a/ reinforcement signal (observed)", fontsize=9)
    axes[1].set_title("b/ corresponding deterministic error (m)", fontsize=9)
    axes[1].set_yscale("log")
    for ax in axes:
        ax.set_xlabel("iteration")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


