"""``lipsync edit``: a local browser editor for a bank's control lines with a live morph preview.

:mod:`.server` holds the API and the state (drafts, the background flow worker); the page is
plain HTML/JS/SVG/CSS in ``static/`` (no build step, no CDN: it works offline). Security comes
from :mod:`lipsync.web`: 127.0.0.1, a per-session token, Host/Origin checks, bounded bodies,
reads confined to the bank folder and the only write being the bank's own bank.yaml.
"""

from .server import Editor, make_app

__all__ = ["Editor", "make_app"]
