"""Hostile media files (issue 32, item 1): ffmpeg must never read a file the input points at.

An HLS playlist, a concat list, a DASH manifest, ... names another file (by path, ``file:``,
``subfile:``, ``concat:`` URLs); ffmpeg's own probe opens that file when left to itself.
"Secret" files outside the job folder hold a 1234 Hz tone; every way lipsync opens a user's
media (audio decoding, the audio check before muxing, the mux itself, video probing, and
``lipsync serve``'s render job) is fed containers pointing at them. The contract: an
:class:`~lipsync.errors.InputError` naming the file, or output without the tone -- never the
secret's sound. Hypothesis draws container x reference form x target x upload extension
(quick profile here; ``make fuzz`` runs many more).
"""

from __future__ import annotations

import subprocess
import time
from pathlib import Path

import httpx
import imageio_ffmpeg
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from hypothesis_profiles import FUZZ, PROFILE
from lipsync.encode import open_writer
from lipsync.encode.ffmpeg import check_audio
from lipsync.errors import InputError
from lipsync.face.video import probe_video
from lipsync.speech.audio import load_audio

FFMPEG = imageio_ffmpeg.get_ffmpeg_exe()
#: The secret's pitch: far from speech formants' harmonics of the other test sounds.
TONE_HZ = 1234.0

#: Containers that reference another file, each as ffmpeg understands it.
CONTAINERS = {
    "hls": "#EXTM3U\n#EXT-X-VERSION:3\n#EXT-X-TARGETDURATION:2\n#EXTINF:2.0,\n{ref}\n#EXT-X-ENDLIST\n",
    "hls-master": "#EXTM3U\n#EXT-X-STREAM-INF:BANDWIDTH=1000\n{ref}\n",
    "ffconcat": "ffconcat version 1.0\nfile '{ref}'\n",
    "concat-list": "file '{ref}'\n",
    "dash": ('<?xml version="1.0"?><MPD xmlns="urn:mpeg:dash:schema:mpd:2011" type="static" '
             'mediaPresentationDuration="PT2S" minBufferTime="PT1S"><Period><AdaptationSet mimeType="audio/mp4">'
             '<Representation id="a" bandwidth="1000"><BaseURL>{ref}</BaseURL></Representation>'
             '</AdaptationSet></Period></MPD>\n'),
    "sdp": "v=0\no=- 0 0 IN IP4 127.0.0.1\ns=x\nc=IN IP4 127.0.0.1\nt=0 0\nm=audio 5004 RTP/AVP 0\na=x:{ref}\n",
}
#: How a container may name the target.
REFS = {
    "path": "{p}",
    "file": "file:{p}",
    "file-url": "file://{p}",
    "subfile": "subfile,,start,0,end,0,,:{p}",
    "concat": "concat:{p}|{p}",
    "cache": "cache:{p}",
    "async": "async:file:{p}",
    "relative": "../secret/{name}",
    "crypto": "crypto:{p}",
    "tee": "tee:{p}|{p}",
    "concatf": "concatf:{p}",
}
TARGETS = ("secret.mp3", "secret.ts", "secret.wav")
EXTENSIONS = (".m3u8", ".m3u", ".wav", ".mp3", ".mp4", ".ts", ".ffconcat", ".txt", ".mpd", ".sdp", ".ogg")

#: Examples per test: each costs an ffmpeg start or three (~40 ms each).
EXAMPLES = 48 if PROFILE == "quick" else 2000


@pytest.fixture(scope="module")
def secrets(tmp_path_factory):
    root = tmp_path_factory.mktemp("hostile")
    secret = root / "secret"
    secret.mkdir()
    for name in TARGETS:
        subprocess.run([FFMPEG, "-v", "error", "-y", "-f", "lavfi", "-i",
                        f"sine=frequency={TONE_HZ:g}:duration=2:sample_rate=16000", "-ac", "1",
                        str(secret / name)], check=True)
    (root / "job").mkdir()
    return root


def _leaks(samples: np.ndarray, rate: int = 16000) -> bool:
    """Whether most of the energy of ``samples`` is the secret's tone."""
    x = samples.astype(np.float64)
    if len(x) < rate // 10 or np.sqrt(np.mean(x * x)) < 50:
        return False
    spectrum = np.abs(np.fft.rfft(x)) ** 2
    freqs = np.fft.rfftfreq(len(x), 1.0 / rate)
    return spectrum[np.abs(freqs - TONE_HZ) < 30].sum() > 0.5 * spectrum.sum()


def _decode(path: Path) -> np.ndarray:
    """Audio of ``path`` decoded by a plain ffmpeg (the test's own reference decoder)."""
    out = subprocess.run([FFMPEG, "-v", "error", "-i", str(path), "-map", "0:a:0", "-ac", "1", "-ar", "16000",
                          "-f", "s16le", "-"], capture_output=True).stdout
    return np.frombuffer(out[: len(out) // 2 * 2], "<i2")


def _hostile(root: Path, container: str, ref: str, target: str, ext: str, n: int) -> Path:
    p = str(root / "secret" / target)
    text = CONTAINERS[container].format(ref=REFS[ref].format(p=p, name=target))
    path = root / "job" / f"upload{n}{ext}"
    path.write_text(text)
    return path


def test_the_secret_is_what_the_check_detects(secrets):
    # the detector itself: the secret leaks through a plain ffmpeg reading an .m3u8 playlist
    playlist = _hostile(secrets, "hls", "path", "secret.mp3", ".m3u8", 0)
    assert _leaks(_decode(playlist))
    assert _leaks(load_audio(secrets / "secret" / "secret.wav"))  # a real file is still read
    assert not _leaks(np.zeros(16000, np.int16))


#: The extension each container is recognised by (ffmpeg's hls probe wants .m3u8/.m3u).
NATURAL = {"hls": (".m3u8", ".m3u"), "hls-master": (".m3u8",), "ffconcat": (".ffconcat", ".txt"),
           "concat-list": (".txt",), "dash": (".mpd",), "sdp": (".sdp",)}

_counter = iter(range(1, 10 ** 9))


@st.composite
def _case(draw):
    container = draw(st.sampled_from(sorted(CONTAINERS)))
    # half the time the name ffmpeg recognises the container by, else any upload name
    ext = draw(st.one_of(st.sampled_from(NATURAL[container]), st.sampled_from(EXTENSIONS)))
    return container, draw(st.sampled_from(sorted(REFS))), draw(st.sampled_from(TARGETS)), ext


@settings(FUZZ, max_examples=EXAMPLES)
@given(case=_case())
@example(case=("hls", "path", "secret.mp3", ".m3u8"))    # the round-three report
@example(case=("hls", "subfile", "secret.ts", ".m3u"))
@example(case=("ffconcat", "relative", "secret.wav", ".ffconcat"))
def test_decoding_a_hostile_container_never_gives_the_outside_file(secrets, case):
    container, ref, target, ext = case
    path = _hostile(secrets, container, ref, target, ext, next(_counter))
    try:
        samples = load_audio(path)
    except InputError as exc:
        assert str(path) in str(exc)
    else:
        assert not _leaks(samples), case
    # the check before muxing, and the video side, refuse it or see no sound
    try:
        check_audio(path)
    except InputError as exc:
        assert str(path) in str(exc)
    else:
        raise AssertionError(f"{case}: accepted as audio")
    try:
        info = probe_video(path)
    except InputError as exc:
        assert str(path) in str(exc)
    else:
        assert not info.has_audio, case


@pytest.mark.parametrize("container, ext", [("hls", ".m3u8"), ("ffconcat", ".ffconcat"), ("hls", ".m3u")])
def test_muxing_a_hostile_soundtrack_never_gives_the_outside_file(secrets, tmp_path, container, ext):
    audio = _hostile(secrets, container, "path", "secret.ts", ext, next(_counter))
    out = tmp_path / "out.mp4"
    try:
        with open_writer(out, fps=10, size=(16, 16), audio=audio, quiet=True, frames=20) as w:
            for _ in range(20):
                w.write(np.zeros((16, 16, 3), np.uint8))
    except InputError as exc:
        assert str(audio) in str(exc)
        assert not out.exists()
    else:
        assert not _leaks(_decode(out))


def test_serve_render_job_of_an_hls_playlist_is_refused(secrets, tmp_path):
    # the round-three hole: POST a playlist as audio, get the outside file's sound in the mp4
    from lipsync.server import LiveServer, ServeConfig, WS_MAX_MESSAGE
    from lipsync.web import Session, start_in_thread

    session = Session.open("127.0.0.1", 0)
    server = LiveServer(ServeConfig(), session=session)
    handle = start_in_thread(server.app, session, ws_max_size=WS_MAX_MESSAGE)
    try:
        playlist = CONTAINERS["hls"].format(ref=str(secrets / "secret" / "secret.mp3")).encode()
        for name, fmt in (("a.m3u8", "audio"), ("a.m3u8", None), ("a.mp3", "audio"), ("a.wav", None)):
            url = session.url("/api/render") + f"&name={name}" + (f"&format={fmt}" if fmt else "")
            r = httpx.post(url, content=playlist)
            assert r.status_code in (202, 400), r.text
            if r.status_code == 400:
                continue
            job = r.json()["job"]
            deadline = time.monotonic() + 60
            while True:
                state = httpx.get(session.url(f"/api/jobs/{job}")).json()
                if state["state"] in ("done", "error") or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
            if state["state"] == "done":
                out = tmp_path / f"{job}.mp4"
                out.write_bytes(httpx.get(session.url(state["video"])).content)
                assert not _leaks(_decode(out)), (name, fmt)
            else:
                assert state["state"] == "error" and "lipsync-serve" not in state["error"], state
    finally:
        handle.stop()
        server.close()
        session.close()


def test_an_image2_pattern_name_never_reads_its_siblings(tmp_path):
    # ffmpeg's image2 demuxer reads "frame%03d.png" as frame001.png, frame002.png, ...: files
    # the name only points at. The literal file is refused, the sequence never read.
    import cv2

    for i in range(1, 4):
        cv2.imwrite(str(tmp_path / f"frame{i:03d}.png"), np.full((16, 16, 3), 60 * i, np.uint8))
    pattern = tmp_path / "frame%03d.png"
    pattern.write_bytes((tmp_path / "frame001.png").read_bytes())
    with pytest.raises(InputError, match="not a sound or video container"):
        probe_video(pattern)
