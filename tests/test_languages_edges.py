"""Speech at the very edge of the audio (issue 38 item 14): a held-out Finnish sentence whose
first sound starts at 0 ms, spoken by espeak-ng (which reports each phoneme's time: the
truth), lost its transcript to the phone loop (3 of 4 words left out); it must come back
whole, each word where espeak-ng said it.
"""

import warnings
import wave

import numpy as np
import pytest

pytest.importorskip("espeakng_loader")

from lipsync.bench.languages import fresh_synthesis  # noqa: E402  (order-independent speech)
from lipsync.phonetics import g2p  # noqa: E402
from lipsync.speech.align import align  # noqa: E402
from lipsync.speech.audio import load_audio  # noqa: E402

TEXT = "Menemme bussilla mummolaan maanantaina."


def test_speech_starting_at_the_first_sample_keeps_its_transcript(tmp_path):
    pcm22, phonemes = fresh_synthesis(TEXT, "fi")
    with wave.open(str(tmp_path / "fi.wav"), "wb") as w:
        w.setnchannels(1)
        w.setsampwidth(2)
        w.setframerate(g2p.SYNTH_RATE)
        w.writeframes(np.ascontiguousarray(pcm22, np.int16).tobytes())
    pcm = load_audio(tmp_path / "fi.wav")
    assert phonemes[0][0] < 0.01 and phonemes[0][2] == "m"  # the case: speech from the first sample
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        al = align(pcm, TEXT, lang="fi", jobs=1)
    assert al.words.labels() == ["Menemme", "bussilla", "mummolaan", "maanantaina"]
    assert not al.recognised and not al.skipped and al.confidence > 0.8
    assert not [w for w in caught if "transcript" in str(w.message)]  # the failed first try is not reported
    # each word starts within 50 ms of espeak-ng's first phoneme of it: m, b, m, m
    starts = [a for a, _, p in phonemes if p in ("m", "b")]
    for w, near in zip(al.words, (0.0, starts[3], starts[4], starts[7])):
        assert abs(w.start - near) < 0.05, (w.label, w.start, near)
    assert al.phones[0].start >= 0.0 and al.phones[-1].end <= len(pcm) / 16000 + 1e-9
