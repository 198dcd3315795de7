"""The bar chart every benchmark report draws (report.png): this run beside the paper, titled with the policy."""
from __future__ import annotations

import pathlib
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

_OURS = (167, 121, 78)  # BGR
_PAPER = (170, 170, 170)
_FONT = cv2.FONT_HERSHEY_SIMPLEX


@dataclass(frozen=True)
class Bar:
    label: str  # e.g. 'SA-SI pick_place'
    percent: float | None  # this run; None: not run
    paper: float | None  # the paper's figure; None: the paper has none
    counts: str = ''  # e.g. '49/50', drawn beside this run's bar
    bold: bool = False  # a total


def bar_chart(path: pathlib.Path, title_lines: Sequence[str], bars: Sequence[Bar]) -> None:
    """Horizontal bars, 0-100 %: this run (blue) above the paper (gray); the title lines on top."""
    row_height, left, width = 26, 300, 460
    top = 16 + 20 * len(title_lines) + 22
    image = np.full((top + row_height * len(bars) + 10, left + width + 90, 3), 255, np.uint8)
    for index, line in enumerate(title_lines):
        cv2.putText(image, line, (10, 22 + 20 * index), _FONT, 0.5 if index else 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.putText(image, 'success % (blue: this run, gray: paper)', (10, top - 8), _FONT, 0.45, (60, 60, 60), 1,
                cv2.LINE_AA)
    for index, bar in enumerate(bars):
        y = top + index * row_height
        cv2.putText(image, bar.label, (10, y + 16), _FONT, 0.45, (0, 0, 0), 2 if bar.bold else 1, cv2.LINE_AA)
        if bar.paper is not None:
            cv2.rectangle(image, (left, y + 12), (left + int(width * bar.paper / 100), y + 20), _PAPER, -1)
        if bar.percent is not None:
            ours = int(width * bar.percent / 100)
            cv2.rectangle(image, (left, y + 2), (left + ours, y + 11), _OURS, -1)
            text = f'{bar.percent:.0f}' + (f' ({bar.counts})' if bar.counts else '')
            cv2.putText(image, text, (left + ours + 4, y + 11), _FONT, 0.35, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.imwrite(str(path), image)
