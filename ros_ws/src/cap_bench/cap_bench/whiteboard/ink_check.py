"""Judging the ink on the board against the shapes an episode asked for (pure NumPy and OpenCV).

Two figures per drawing, in millimetres on the board, from the ink image (one pixel per INK_RESOLUTION):
- the ink's distance to the target curve: for every inked pixel, how far its centre lies from the nearest point of
  the target polylines (mean and 95th percentile); a line drawn exactly has half the tip's width (1.5 mm) at most;
- coverage: the fraction of the target curve (sampled every millimetre) that has ink within COVER_RADIUS.
A drawing passes with a 95th percentile of at most MAX_P95_MM and a coverage of at least MIN_COVERAGE. An erased
board passes when at most MAX_INK_LEFT_PX inked pixels are left (a few square millimetres).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np
from cap_whiteboard import board

MAX_P95_MM = 3.0
MIN_COVERAGE = 0.95
COVER_RADIUS_MM = 2.0
MAX_INK_LEFT_PX = 10


@dataclass(frozen=True)
class InkVerdict:
    success: bool
    reason: str
    mean_mm: float = 0.0
    p95_mm: float = 0.0
    coverage: float = 0.0
    ink_pixels: int = 0

    def figures(self) -> dict:
        return {'mean_mm': round(self.mean_mm, 3), 'p95_mm': round(self.p95_mm, 3),
                'coverage': round(self.coverage, 4), 'ink_pixels': self.ink_pixels}


def _pixels(points: np.ndarray) -> np.ndarray:
    """(N, 2) world x, y -> (N, 2) fractional (column, row) of the ink image (pixel centres at integers)."""
    col = (points[:, 0] - board.X_RANGE[0]) / board.INK_RESOLUTION - 0.5
    row = (board.Y_RANGE[1] - points[:, 1]) / board.INK_RESOLUTION - 0.5
    return np.column_stack([col, row])


def _distance_to(mask: np.ndarray) -> np.ndarray:
    """Per pixel, the distance [px] to the nearest pixel set in `mask` (exact Euclidean)."""
    return cv2.distanceTransform((mask == 0).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def distance_to_polylines(points: np.ndarray, targets: Sequence[np.ndarray]) -> np.ndarray:
    """(N,) distance of each point (N, 2) to the nearest segment of the target polylines (same units)."""
    best = np.full(len(points), np.inf)
    for target in targets:
        target = np.asarray(target, dtype=float)
        if len(target) == 1:
            best = np.minimum(best, np.linalg.norm(points - target[0], axis=1))
            continue
        for start, end in zip(target[:-1], target[1:]):
            segment = end - start
            length_sq = float(segment @ segment)
            t = np.zeros(len(points)) if length_sq == 0 else np.clip((points - start) @ segment / length_sq, 0, 1)
            best = np.minimum(best, np.linalg.norm(points - (start + t[:, None] * segment), axis=1))
    return best


def samples_along(target: np.ndarray, step: float) -> np.ndarray:
    """Points every `step` metres along the polyline (its vertices included)."""
    out = [target[:1]]
    for start, end in zip(target[:-1], target[1:]):
        count = max(1, int(np.ceil(np.linalg.norm(end - start) / step)))
        out.append(start + (np.arange(1, count + 1) / count)[:, None] * (end - start))
    return np.vstack(out)


def check_drawing(ink: np.ndarray, targets: Sequence[np.ndarray]) -> InkVerdict:
    """Does the ink show the target polylines (and nothing else)? See the module docstring."""
    inked = ink > 0
    count = int(inked.sum())
    if count == 0:
        return InkVerdict(False, 'there is no ink on the board')
    mm_per_px = board.INK_RESOLUTION * 1000.0
    rows, cols = np.nonzero(inked)
    centres = np.column_stack([board.X_RANGE[0] + (cols + 0.5) * board.INK_RESOLUTION,
                               board.Y_RANGE[1] - (rows + 0.5) * board.INK_RESOLUTION])
    distances = distance_to_polylines(centres, [np.asarray(t, dtype=float) for t in targets]) * 1000.0
    mean, p95 = float(distances.mean()), float(np.percentile(distances, 95))
    to_ink = _distance_to(inked.astype(np.uint8)) * mm_per_px
    samples = np.vstack([samples_along(np.asarray(t, dtype=float), board.INK_RESOLUTION) for t in targets])
    cols, rows = np.round(_pixels(samples)).astype(int).T
    inside = (rows >= 0) & (rows < ink.shape[0]) & (cols >= 0) & (cols < ink.shape[1])
    covered = np.zeros(len(samples), dtype=bool)
    covered[inside] = to_ink[rows[inside], cols[inside]] <= COVER_RADIUS_MM
    coverage = float(covered.mean())
    problems = []
    if p95 > MAX_P95_MM:
        far = float(distances.max())
        problems.append(f'ink strays from the target: 95th percentile {p95:.1f} mm > {MAX_P95_MM} mm '
                        f'(farthest {far:.1f} mm)')
    if coverage < MIN_COVERAGE:
        gap = samples[~covered][0]
        problems.append(f'{coverage:.0%} of the target is inked (< {MIN_COVERAGE:.0%}); first gap at '
                        f'({gap[0]:.3f}, {gap[1]:.3f})')
    return InkVerdict(not problems, '; '.join(problems), mean, p95, coverage, count)


def check_erased(ink: np.ndarray) -> InkVerdict:
    """Is the board clean (at most MAX_INK_LEFT_PX inked pixels)?"""
    count = int((ink > 0).sum())
    if count <= MAX_INK_LEFT_PX:
        return InkVerdict(True, '', ink_pixels=count, coverage=0.0)
    rows, cols = np.nonzero(ink)
    x = board.X_RANGE[0] + (cols.mean() + 0.5) * board.INK_RESOLUTION
    y = board.Y_RANGE[1] - (rows.mean() + 0.5) * board.INK_RESOLUTION
    return InkVerdict(False, f'{count} mm^2 of ink left (> {MAX_INK_LEFT_PX}), centred near ({x:.3f}, {y:.3f})',
                      ink_pixels=count)


__all__ = ['COVER_RADIUS_MM', 'InkVerdict', 'MAX_INK_LEFT_PX', 'MAX_P95_MM', 'MIN_COVERAGE', 'check_drawing',
           'check_erased', 'distance_to_polylines', 'samples_along']
