"""Live talking heads: frames for a playback clock from events pushed as they arrive.

* :mod:`.causal` — :class:`CausalSequencer`: the sequencer's rules on a growing track,
  with the look-ahead they imply (:data:`LOOKAHEAD_S`, 380 ms);
* :mod:`.animator` — :class:`LiveAnimator`: label mapping, thread safety, rendering (onto
  the bank's idle plate when it has one), the end of an audio stream (``finish_audio``);
* :mod:`.pool` — :class:`RendererPool`: renderers shared by many animators, and
  :func:`~.pool.shared_plate`: a bank's plate decoded once per process;
* :mod:`.audio` — the audio front-end of :meth:`LiveAnimator.feed_audio`: resampler, voice
  gate, pocketsphinx's phone loop decoded in 20 ms blocks;
* :mod:`lipsync.pipeline.liveclip` (the pipeline room, above this one) — what a live session
  fed a recording shows (``render/cues --live``).

``lipsync serve`` (:mod:`lipsync.server`) streams these frames to browsers.
"""

from .animator import AUDIO_LOOKAHEAD_S, LiveAnimator, replay_specs
from .causal import LOOKAHEAD_S, RELAX_S, CausalSequencer
from .pool import RendererPool

__all__ = ["LiveAnimator", "replay_specs", "CausalSequencer", "RendererPool", "LOOKAHEAD_S", "RELAX_S",
           "AUDIO_LOOKAHEAD_S"]
