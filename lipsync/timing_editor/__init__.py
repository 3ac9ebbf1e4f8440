"""``lipsync edit-timeline``: a local browser editor for a recording's lip-sync timing.

The animator's correction pass after alignment (what Papagayo-NG is for): the recording's
waveform with its words, phones and visemes as tiers, boundaries dragged (snapped to frames),
words retyped (their phones from the lexicon or the language's letters-to-sounds), phones
and visemes changed, and the bank's real morphed mouth previewed in sync with playback.
:mod:`.model` holds the edited timeline (validation, frame grid, loading, saving through the
readers and writers); :mod:`.server` the API under the page; the page is plain
HTML/JS/CSS/canvas in ``static/`` (no build step, no CDN). Security is :mod:`lipsync.web`'s,
as for ``lipsync edit``: 127.0.0.1, a session token, Host/Origin checks, bounded bodies.
"""

from .model import MAX_AUDIO_S, SAVE_FORMATS, Context, TimingDoc
from .server import TimingEditor, make_app

__all__ = ["TimingEditor", "make_app", "TimingDoc", "Context", "SAVE_FORMATS", "MAX_AUDIO_S"]
