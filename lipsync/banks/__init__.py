"""Making and changing banks: writing bank.yaml (:mod:`.yamlio`), viseme names from file names
(:mod:`.names`) and a starting bank from a folder of images (:mod:`.init`).

This room is apart from :mod:`lipsync.editor` on purpose: ``lipsync init`` and every script
that writes a bank need it without a web server, and the editor's save uses the same writer,
so both produce the same readable YAML. Reading and validating stays in :mod:`lipsync.bank`.
"""

from .init import init_bank
from .yamlio import dump_bank, header_comments, write_bank_text

__all__ = ["init_bank", "dump_bank", "header_comments", "write_bank_text"]
