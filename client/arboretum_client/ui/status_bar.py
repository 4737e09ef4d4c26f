"""Status bar: the last message, the mode, revision, hand legend, and a progress bar per server job."""

from __future__ import annotations

from arboretum_client.net import JobStatus
from arboretum_client.tools.state import ClientState

from .widgets import DIM, LINE_H, TEXT, Canvas

HEIGHT = 26


def draw(c: Canvas, s: ClientState, jobs: dict[int, JobStatus]) -> None:
    w, h = c.size
    top = h - HEIGHT - (LINE_H + 4) * len(jobs)
    c.draw.rectangle((0, top, w, h), fill=(24, 28, 34, 215))
    y = top + 4
    for job in jobs.values():
        c.text((10, y), f"{job.name} {job.message}"[:30], DIM)
        c.bar((230, y + 3, min(w - 10, 530), y + LINE_H - 3), job.fraction)
        y += LINE_H + 4
    c.text((10, h - HEIGHT + 5), s.status[:90], TEXT)
    right = f"{s.mode} | rev {s.revision} | left hand blue, right hand red"
    c.text((max(w - 8 * len(right) + 40, w // 2), h - HEIGHT + 5), right, DIM)
