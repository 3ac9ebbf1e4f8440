"""Speed figure of ``lipsync edit`` (registered in :data:`lipsync.bench.FIGURES` as ``editor``).

On a copy of the default subject (512x512, 41 lines, 9 visemes), served by the real editor
app on uvicorn at 127.0.0.1 and called over HTTP like the page does:

* ``save``: POST /api/save of a symmetric edit of one viseme (validation with the real loader,
  atomic write);
* ``save -> preview``: from sending the save to having the PNG of the edited pair's
  in-between frame, the default way (the preview waits up to ``PREVIEW_WAIT_S`` for the
  pair's new flows, then renders with the flow method) against the Beier-Neely fallback at
  once (``PREVIEW_WAIT_S = 0``);
* ``preview, flows ready``: one frame while playing (the flow method);
* ``background flows``: until all pairs of the edited viseme (8) are recomputed.
"""

from __future__ import annotations

import shutil
import statistics
import time
from typing import List

from .._data import default_bank_dir
from . import FIGURES, Context


def _moved(doc, viseme: str, dx: float):
    lines = doc["visemes"][viseme]["lines"]
    for name, sign in (("upper_outer_l", -1), ("upper_outer_r", 1)):
        p = lines[name][0]
        lines[name][0] = [p[0] + sign * dx, p[1]]
    return doc


@FIGURES.decorator("editor")
def editor_figure(ctx: Context, rows: List[dict]) -> None:
    import copy

    import httpx

    from ..editor import server
    from ..morphing.store import FlowStore
    from ..web import Session, start_in_thread

    bank = shutil.copytree(default_bank_dir(), ctx.tmp / "editor-bank", ignore=shutil.ignore_patterns(".lipsync"))
    ed = server.Editor(bank, store=FlowStore(ctx.tmp / "editor-store"))
    session = Session.open()
    running = start_in_thread(server.make_app(ed, session), session)
    repeat = 2 if ctx.quick else 5
    try:
        client = httpx.Client(base_url=session.origin, headers={"X-Lipsync-Token": session.token}, timeout=120)
        doc = client.get("/api/bank").json()["doc"]
        ed.worker.wait_idle(1200)  # a warm store, as after `lipsync preprocess`
        preview = "/api/preview?from=X&to=D&alpha=0.5"
        times = {"save": [], "flow": [], "beier-neely": [], "play": [], "background": []}
        methods = {"flow": set(), "beier-neely": set()}
        step = 0
        wait = server.PREVIEW_WAIT_S
        for mode in ("flow", "beier-neely"):
            server.PREVIEW_WAIT_S = wait if mode == "flow" else 0.0
            for _ in range(repeat):
                step += 1
                edited = _moved(copy.deepcopy(doc), "D", 0.5 * step)
                t0 = time.perf_counter()
                assert client.post("/api/save", json={"doc": edited}).json()["ok"]
                t1 = time.perf_counter()
                r = client.get(preview)
                t2 = time.perf_counter()
                methods[mode].add(r.headers["x-lipsync-method"])
                times[mode].append(t2 - t0)
                if mode == "flow":
                    times["save"].append(t1 - t0)
                    ed.worker.wait_idle(1200)
                    times["background"].append(time.perf_counter() - t0)
                    t3 = time.perf_counter()
                    client.get(preview.replace("0.5", "0.55"))
                    times["play"].append(time.perf_counter() - t3)
                else:
                    ed.worker.wait_idle(1200)
    finally:
        server.PREVIEW_WAIT_S = wait
        running.stop()
        ed.close()
        session.close()

    def ms(xs):
        return round(statistics.median(xs) * 1e3, 1)

    rows.append({"figure": "editor", "measure": "save (validate + atomic write)", "ms": ms(times["save"]),
                 "method": "", "ratio": ""})
    rows.append({"figure": "editor", "measure": "save -> updated preview (default: waits for the pair's flows)",
                 "ms": ms(times["flow"]), "method": "/".join(sorted(methods["flow"])),
                 "ratio": round(ms(times["flow"]) / ms(times["beier-neely"]), 2)})
    rows.append({"figure": "editor", "measure": "save -> updated preview (beier-neely at once)",
                 "ms": ms(times["beier-neely"]), "method": "/".join(sorted(methods["beier-neely"])),
                 "ratio": 1.0})
    rows.append({"figure": "editor", "measure": "preview frame, flows ready (play)", "ms": ms(times["play"]),
                 "method": "flow", "ratio": round(ms(times["play"]) / ms(times["beier-neely"]), 2)})
    rows.append({"figure": "editor", "measure": "save -> all 8 pairs of the viseme recomputed",
                 "ms": ms(times["background"]), "method": "", "ratio": ""})
