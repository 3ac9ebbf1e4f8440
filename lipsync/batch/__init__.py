"""Batch rendering: a manifest of clips rendered on a dask.distributed cluster (``lipsync batch``).

One module per stage, each stage once:

* :mod:`.manifest` -- read and check every row (CSV or JSON lines), all problems with their
  line numbers before anything runs;
* :mod:`.sidecar` -- each clip's content key and the ``.lipsync.json`` sidecar beside its
  output, so that current outputs are skipped (resumable, idempotent);
* :mod:`.bankpack` -- banks travel by content: packed on the client, unpacked once per
  worker machine into a local cache, loaded once per worker process;
* :mod:`.worker` -- the tasks: one per viseme pair (flows computed once per cluster,
  shipped to the workers that need them) and one per clip (:func:`lipsync.pipeline.clip.render_clip`,
  the pipeline of ``lipsync render``);
* :mod:`.run` -- the client: connect (a LocalCluster on 127.0.0.1 or a running scheduler),
  submit through a bounded window, write outputs atomically, report.

Examples
--------
>>> from lipsync.batch import read_manifest, run_batch
>>> report = run_batch("clips.csv", "out/", workers=2)   # doctest: +SKIP
>>> print(report.summary())                               # doctest: +SKIP
6 clips: 5 done, 0 skipped, 1 failed; 11.5 s of video in 9.8 s wall (1.17x real time); ...
"""

from .bankpack import BankPack, local_bank, pack_bank
from .manifest import FIELDS, ClipJob, ManifestError, read_manifest
from .run import BatchReport, ClipResult, connect, run_batch
from .sidecar import clip_key

__all__ = ["BankPack", "BatchReport", "ClipJob", "ClipResult", "FIELDS", "ManifestError", "clip_key",
           "connect", "local_bank", "pack_bank", "read_manifest", "run_batch"]
