"""Reconstruction samples for the paper's figures: Fig. 16 (V_a) and Fig. 14 (V_s).

Fig. 14 shows a frame with the car on the road and one with the car on the grass. CarRacing draws
the car at a fixed screen position (bottom centre: rows 66-77, columns 44-51 of the 96x96 frame)
once the intro zoom of the first second (50 frames) is over, so the surface under the car is read
off the pixels of that box that are not the car's own (red body, black wheels): grey road
(R = G = B, about 102-107) or green grass (G well above R and B).
"""
from __future__ import annotations

import logging

import numpy as np
import torch

from plls_bench.repr.fit import Split, reconstruct
from plls_bench.repr.models import VAE

log = logging.getLogger(__name__)

N_ACTIONS = 200                        # Fig. 16: "the first 200 of the test data"
CAR_ROWS, CAR_COLS = slice(66, 78), slice(44, 52)  # the car's box in CarRacing's 96x96 frame
INTRO_FRAMES = 50                      # CarRacing zooms in during its first second at 50 FPS
MIN_SHARE = 0.5                        # a surface must cover more than half the uncovered pixels in the box


def surface_under_car(frames: np.ndarray) -> np.ndarray:
    """``(N,)`` labels ``road`` / ``grass`` / ``mixed`` for uint8 frames ``(N, 3, 96, 96)``."""
    box = frames[:, :, CAR_ROWS, CAR_COLS].astype(np.int16)
    r, g, b = box[:, 0], box[:, 1], box[:, 2]
    car = (r > g + 40) | (box.max(axis=1) < 50)          # red body or black wheels
    grass = (g > r + 30) & (g > b + 30) & ~car
    road = (np.abs(r - g) < 25) & (np.abs(g - b) < 25) & (r >= 60) & (r <= 170) & ~car
    free = np.maximum((~car).sum(axis=(1, 2)), 1)
    labels = np.full(len(frames), "mixed", dtype="<U5")
    labels[road.sum(axis=(1, 2)) / free > MIN_SHARE] = "road"
    labels[grass.sum(axis=(1, 2)) / free > MIN_SHARE] = "grass"
    return labels


def action_samples(model: VAE, test: Split, device: torch.device) -> dict[str, np.ndarray]:
    """The first 200 test actions ``(200, A)`` with their reconstructions through the VAE (z
    sampled, as ``test_mse``) and at the posterior mean (``reconstructions_mean``)."""
    x = test.batch(np.arange(min(N_ACTIONS, len(test))), device)
    return {"actions": x.cpu().numpy(), "reconstructions": reconstruct(model, x, sample=True).cpu().numpy(),
            "reconstructions_mean": reconstruct(model, x, sample=False).cpu().numpy()}


def state_samples(model: VAE, test: Split, steps: np.ndarray, device: torch.device) -> dict[str, np.ndarray]:
    """The first test frame with the car on the road and the first on the grass (after the intro
    zoom; ``steps[i]`` is test frame i's step in its episode), with their reconstructions.

    A surface the test split never shows is left out and logged, so ``labels`` may hold fewer
    than two entries: under the uniform random policy the car seldom leaves the road.
    """
    frames = test.array[test.index]
    labels = surface_under_car(frames)
    picked, names = [], []
    for surface in ("road", "grass"):
        hits = np.flatnonzero((labels == surface) & (steps >= INTRO_FRAMES))
        if len(hits):
            picked.append(int(hits[0]))
            names.append(surface)
        else:
            log.warning("no test frame shows the car on the %s: Fig. 14 gets no %s example", surface, surface)
    rows = np.asarray(picked, dtype=np.int64)
    originals = frames[rows]
    x = test.batch(rows, device)
    return {"originals": originals, "reconstructions": _to_uint8(reconstruct(model, x, sample=True)),
            "reconstructions_mean": _to_uint8(reconstruct(model, x, sample=False)),
            "labels": np.asarray(names, dtype="<U5"), "test_index": rows}


def _to_uint8(frames: torch.Tensor) -> np.ndarray:
    return (frames.clamp(0, 1) * 255).round().to(torch.uint8).cpu().numpy()
