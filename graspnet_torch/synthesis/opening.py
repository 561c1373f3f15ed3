"""Open postures for power grasps (:mod:`~graspnet_torch.synthesis.power`): which way each finger
joint closes and where it starts from, for a batch of palm poses.

A joint closes toward the side whose cosine to its pad's forward direction
(:func:`~graspnet_torch.synthesis.closing.pad_forward`) reaches ``FORWARD``, else it holds; the
opposing finger's joints whose cosine is weaker than ``SURE`` (a thumb's rotation) close up, down or
hold, a third of the poses each. Each closing joint opens ``OPEN`` of its range from the limit away
from closing; a joint that bends either way opens from straight.
"""

from __future__ import annotations

import numpy as np

from graspnet_torch.synthesis.closing import FORWARD

__all__ = ["OPEN", "SURE", "closing_directions", "draw_open", "open_postures"]

OPEN = (0.0, 0.05)  # a finger's open posture: this fraction of each joint's range from the limit away from closing
SURE = 0.7  # a joint's cosine to its pad's forward direction from which its closing direction is sure


def draw_open(forward: np.ndarray, o: int, lo: np.ndarray, hi: np.ndarray, n: int, rng: np.random.Generator
              ) -> tuple[np.ndarray, np.ndarray]:
    """``n`` open postures of a hand whose joints move their pads as ``forward`` (F, n_j) says
    (opposing finger row ``o``, joint limits ``lo``, ``hi`` (F, n_j), rad or m): each joint's
    closing direction (n, F, n_j) (:func:`closing_directions`) and the open posture (n, F, n_j)
    (:func:`open_postures`, ``OPEN`` of each range)."""
    direction, held = closing_directions(forward, o, lo, hi, n, rng)
    opened = rng.uniform(*OPEN, (n, *lo.shape)) * (hi - lo)
    return direction, open_postures(direction, held, lo, hi, opened, rng)


def closing_directions(forward: np.ndarray, o: int, lo: np.ndarray, hi: np.ndarray, B: int,
                       rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Each pose's closing direction of every joint (B, F, n) (+1 up, -1 down, 0 held) and where a
    held joint is held (B, F, n; NaN: near its lower limit), from ``forward`` (F, n)
    (:func:`~graspnet_torch.synthesis.closing.pad_forward` at mid-range): a joint closes toward the
    side whose cosine reaches ``FORWARD``, else holds;
    the opposing finger's (row ``o``) joints whose cosine is weaker than ``SURE`` (a thumb's
    rotation, which turns the pad as much as it moves it) close up, down or hold anywhere in their
    range, a third of the poses each."""
    direction = np.where(forward >= FORWARD, 1.0, np.where(forward <= -FORWARD, -1.0, 0.0))
    direction = np.repeat(direction[None], B, axis=0)
    held = np.full(direction.shape, np.nan)  # NaN: near the lower limit, as the open postures draw it
    weak = (np.abs(forward[o]) >= FORWARD) & (np.abs(forward[o]) < SURE)
    if weak.any():  # no draw for a hand without such joints: its poses as before
        direction[:, o, weak] = rng.integers(-1, 2, (B, int(weak.sum())))
        held[:, o] = np.where(weak, lo[o] + rng.random((B, lo.shape[1])) * (hi[o] - lo[o]), np.nan)
    return direction, held


def open_postures(direction: np.ndarray, held: np.ndarray, lo: np.ndarray, hi: np.ndarray, opened: np.ndarray,
                  rng: np.random.Generator) -> np.ndarray:
    """The open postures (B, F, n): each closing joint ``opened`` (B, F, n) from the limit away from
    its closing ``direction`` (B, F, n), each held joint from its lower limit (or at ``held`` where
    that is not NaN); a joint that bends either way (its range across 0) from straight (0) instead,
    except each finger's first closing joint, which opens anywhere from straight to its limit (a
    claw's fingers spread)."""
    straight = (lo < 0) & (hi > 0)
    first = np.cumsum(direction != 0, axis=-1) == 1
    away = np.where(direction < 0, hi, lo)
    spread = np.where(first & (direction != 0), rng.random(direction.shape), 0.0) * away
    start = np.where(straight, spread, away)
    q_open = np.where(direction < 0, start - opened, np.where(direction > 0, start + opened, start + opened))
    return np.where(np.isnan(held), np.where(direction == 0, np.where(straight, 0.0, lo) + opened, q_open), held)
