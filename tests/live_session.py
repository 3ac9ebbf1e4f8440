"""A live audio session as the tests drive it: fed in 20 ms blocks, each frame rendered when
it falls due, the last ones when the audio finishes."""

from __future__ import annotations

from lipsync.live import LiveAnimator
from lipsync.live.audio import BLOCK, RATE


def audio_session(bank, pcm, **options):
    """``(live, {frame index: a copy of its pixels})`` of a session on ``bank`` at 25 fps
    (``options`` go to :class:`~lipsync.live.LiveAnimator`)."""
    live = LiveAnimator(bank, fps=25, **options)
    frames = {}
    for i in range(0, len(pcm), BLOCK):
        for n in live.feed_audio(pcm[i:i + BLOCK], RATE):
            frames[n] = live.frame(n).copy()
    for n in live.finish_audio():
        frames[n] = live.frame(n).copy()
    return live, frames
