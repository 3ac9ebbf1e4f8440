"""Banks: reading and validating them (:mod:`.bank`), writing bank.yaml (:mod:`.yamlio`) and
viseme names from file names (:mod:`.names`). A starting bank from a folder of images is made
one floor up, beside the bank from video (:mod:`lipsync.videobank.photos`): it needs the face
room.

This room is apart from :mod:`lipsync.editor` on purpose: ``lipsync init`` and every script
that writes a bank need it without a web server, and the editor's save uses the same writer,
so both produce the same readable YAML. Reading and validating stays in :mod:`lipsync.banks.bank`.
"""

from .yamlio import dump_bank, header_comments, write_bank_text

__all__ = ["dump_bank", "header_comments", "write_bank_text"]
