"""Live talking heads: frames for a playback clock from events pushed as they arrive.

* :mod:`.causal` — :class:`CausalSequencer`: the sequencer's rules on a growing track,
  with the look-ahead they imply (:data:`LOOKAHEAD_S`, 380 ms);
* :mod:`.animator` — :class:`LiveAnimator`: label mapping, thread safety, rendering.

``lipsync serve`` (:mod:`lipsync.server`) streams these frames to browsers.
"""

from .animator import LiveAnimator
from .causal import LOOKAHEAD_S, RELAX_S, CausalSequencer

__all__ = ["LiveAnimator", "CausalSequencer", "LOOKAHEAD_S", "RELAX_S"]
