"""Status bar: the last message, the mode, revision, hand legend, and a progress bar per server job.

At any output size: the progress bars shrink (and are left out when narrower than ``MIN_BAR``), the job
rows are as many as fit, and the right-hand legend is dropped when it would cover the message.
"""

from __future__ import annotations

from arboretum_client.net import JobStatus
from arboretum_client.tools.state import REFINEMENT, ClientState

from .widgets import CHAR_W, DIM, LINE_H, TEXT, Canvas

HEIGHT = 26
BAR_X0, BAR_X1 = 230, 530
"""The progress bars' span on a wide output."""
MIN_BAR = 24
"""Narrower progress bars are left out."""
MIN_LEGEND_X = 200
"""The legend starts at least this far right, or is left out."""


def job_rows(h: int, jobs: dict[int, JobStatus]) -> int:
    """How many job rows the bar shows on an output ``h`` pixels high."""
    return min(len(jobs), max((h - HEIGHT) // (LINE_H + 4), 0))


def height(h: int, jobs: dict[int, JobStatus]) -> int:
    """The bar's height in pixels, its job rows included."""
    return min(HEIGHT + (LINE_H + 4) * job_rows(h, jobs), h)


def draw(c: Canvas, s: ClientState, jobs: dict[int, JobStatus]) -> None:
    w, h = c.size
    shown = list(jobs.values())[:job_rows(h, jobs)]
    top = h - height(h, jobs)
    c.draw.rectangle((0, top, w, h), fill=(24, 28, 34, 215))
    bar_x0, bar_x1 = min(BAR_X0, w // 2), min(w - 10, BAR_X1)
    y = top + 4
    for job in shown:
        room = (bar_x0 - 20) // CHAR_W if bar_x1 - bar_x0 >= MIN_BAR else (w - 20) // CHAR_W
        c.text((10, y), f"{job.name} {job.message}"[:min(30, max(room, 0))], DIM)
        if bar_x1 - bar_x0 >= MIN_BAR:
            c.bar((bar_x0, y + 3, bar_x1, y + LINE_H - 3), job.fraction)
        y += LINE_H + 4
    rev = s.refine_revision if s.mode == REFINEMENT else s.revision
    right = f"{s.mode} | rev {rev} | left hand blue, right hand red"
    right_x = max(w - 8 * len(right) + 40, w // 2)
    legend = right_x >= MIN_LEGEND_X  # narrower: the legend would cover the message, leave it out
    room = ((right_x if legend else w) - 20) // CHAR_W
    c.text((10, h - HEIGHT + 5), s.status[:min(90, max(room, 0))], TEXT)
    if legend:
        c.text((right_x, h - HEIGHT + 5), right, DIM)
