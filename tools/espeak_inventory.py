"""Walk espeak-ng's phoneme inventory: every phoneme of every phoneme table, as IPA.

espeak-ng's compiled ``phontab`` lists each language's phoneme table (its phoneme
mnemonics and their types). Each vowel and consonant is spoken alone in phoneme input
(``[[x]]``) with ``--ipa``, so espeak-ng itself says which IPA it writes for it:

    espeak-ng -q --ipa -v LANG "[[m1 m2 ...]]"     (one word per phoneme)

Usage (writes the test data tests/test_phonetics.py checks; needs /usr/bin/espeak-ng):

    .venv/bin/python tools/espeak_inventory.py tests/data/phonetics/espeak_inventory.json
"""

from __future__ import annotations

import json
import struct
import subprocess
import sys
from pathlib import Path

DATA = Path("/usr/lib/x86_64-linux-gnu/espeak-ng-data")
N_NAME = 32            # N_PHONEME_TAB_NAME in espeak-ng's phoneme.h
ENTRY = 16             # sizeof(PHONEME_TAB): mnemonic u32, flags u32, program u16, 6 x u8
# PHONEME_TAB.type values (phoneme.h): 2 vowel, 3 liquid, 4 stop, 5 voiced stop, 6 fricative,
# 7 voiced fricative, 8 nasal; 0 pause, 1 stress, 9 virtual are not sounds.
SOUND_TYPES = {2: "vowel", 3: "liquid", 4: "stop", 5: "vstop", 6: "fricative", 7: "vfricative", 8: "nasal"}


# A sentence in each of 34 languages (its own script), spoken as text too: the phones
# espeak-ng's letter-to-sound rules actually produce, with stress, joins and tone digits.
TEXTS = {
    "fr": "Bonjour, je suis un grand œuf brun. Huit chiens jouent dans le jardin avec leurs amis.",
    "de": "Zwölf Boxkämpfer jagen Viktor quer über den großen Sylter Deich. Ich möchte Brötchen.",
    "es": "El veloz murciélago hindú comía feliz cardillo y kiwi. La cigüeña tocaba el saxofón.",
    "it": "Ma la volpe, col suo balzo, ha raggiunto il quieto Fido. Gli gnocchi sono buoni.",
    "pt": "Luís argüia à Júlia que «brações, fé, chá, óxido, pôr, zângão» eram palavras do português.",
    "ru": "Съешь же ещё этих мягких французских булок, да выпей чаю. Щука живёт в реке.",
    "uk": "Чуєш їх, доцю, га? Кумедна ж ти, прощайся без ґольфів!",
    "pl": "Pchnąć w tę łódź jeża lub ośm skrzyń fig. Chrząszcz brzmi w trzcinie.",
    "cs": "Příliš žluťoučký kůň úpěl ďábelské ódy. Řeka teče.",
    "sv": "Flygande bäckasiner söka hwila på mjuka tuvor. Sju sjösjuka sjömän skötte sju skepp.",
    "nl": "Pa's wijze lynx bezag vroom het fikse aquaduct. Scheveningen is een stad.",
    "da": "Høj bly gom vandt fræk sexquiz på wc. Rødgrød med fløde.",
    "nb": "Vår sære Zulu fra badeøya spilte jo whist og quickstep i min taxi.",
    "fi": "Törkylempijävongahdus. Hyvää päivää, mitä kuuluu?",
    "hu": "Árvíztűrő tükörfúrógép. Jó napot kívánok, hogy van?",
    "ro": "Înjurând pițigăiat, zoofobul comandă vexat whisky și tequila.",
    "tr": "Pijamalı hasta yağız şoföre çabucak güvendi. Günaydın, nasılsın?",
    "el": "Ξεσκεπάζω την ψυχοφθόρα βδελυγμία. Καλημέρα, τι κάνεις;",
    "ar": "صِف خَلقَ خَودِ كَمِثلِ الشَّمسِ إِذ بَزَغَت يَحظى الضَجيعُ بِها نَجلاءَ مِعطارِ",
    "fa": "سلام، حال شما چطور است؟ امروز هوا خیلی خوب است.",
    "he": "עטלף אבק נס דרך מזגן שהתפוצץ כי חם. בוקר טוב.",
    "hi": "नमस्ते, आप कैसे हैं? आज मौसम बहुत अच्छा है। ऋषि ने क्षमा माँगी।",
    "bn": "নমস্কার, আপনি কেমন আছেন? আজ আবহাওয়া খুব ভালো।",
    "ta": "வணக்கம், நீங்கள் எப்படி இருக்கிறீர்கள்? இன்று வானிலை நன்றாக இருக்கிறது.",
    "ko": "안녕하세요, 어떻게 지내세요? 오늘 날씨가 정말 좋네요. 키읔 쌍기역 짜장면.",
    "ja": "こんにちは、お元気ですか。今日はとても良い天気です。",
    "cmn": "你好，你今天怎么样？今天天气很好，我们去公园散步吧。",
    "yue": "你好，今日天氣好好，我哋去公園散步啦。",
    "vi": "Xin chào, bạn có khỏe không? Hôm nay trời rất đẹp. Người ta nói tiếng Việt.",
    "th": "สวัสดีครับ คุณสบายดีไหม วันนี้อากาศดีมาก",
    "id": "Selamat pagi, apa kabar? Hari ini cuacanya sangat bagus.",
    "sw": "Habari za asubuhi, rafiki yangu? Leo hali ya hewa ni nzuri sana.",
    "ka": "გამარჯობა, როგორ ხარ? დღეს ძალიან კარგი ამინდია.",
    "hy": "Բարև, ինչպե՞ս ես։ Այսօր եղանակը շատ լավ է։",
}


def tables():
    data = (DATA / "phontab").read_bytes()
    (n_tables,) = struct.unpack_from("<i", data, 0)
    pos = 4
    out = {}
    for _ in range(n_tables):
        n_phonemes = data[pos]
        pos += 4
        name = data[pos:pos + N_NAME].split(b"\0")[0].decode()
        pos += N_NAME
        phonemes = []
        for i in range(n_phonemes):
            mnemonic, _flags, _program, _code, ptype = struct.unpack_from("<IIHBB", data, pos + i * ENTRY)
            text = mnemonic.to_bytes(4, "little").split(b"\0")[0].decode("latin-1")
            if ptype in SOUND_TYPES and text:
                phonemes.append(text)
        pos += n_phonemes * ENTRY
        out[name] = phonemes
    return out


def voices():
    listing = subprocess.run(["espeak-ng", "--voices"], capture_output=True, text=True, check=True).stdout
    return {line.split()[1] for line in listing.splitlines()[1:] if len(line.split()) > 1}


def speak(voice, phonemes):
    words = " ".join(phonemes)
    res = subprocess.run(["espeak-ng", "-q", "--ipa", "-v", voice, f"[[{words}]]"], capture_output=True,
                         text=True, timeout=60)
    return res.stdout.split()


def main(argv):
    have = voices()
    result = {"command": "espeak-ng -q --ipa -v TABLE '[[phoneme ...]]' for each table in phontab",
              "espeak_ng": subprocess.run(["espeak-ng", "--version"], capture_output=True, text=True).stdout.strip(),
              "tables": {}}
    for name, phonemes in tables().items():
        # A table is spoken by the voice of its name (fr: fr-fr); the shared tables (base,
        # base1, base2, consonants) by Esperanto's, whose own table overrides few of them.
        voice = name if name in have else next((v for v in sorted(have) if v.startswith(name + "-")), None)
        if name.startswith(("base", "consonants")):
            voice = "eo"
        if voice is None or not phonemes:
            continue
        # In phoneme input a word's letters are read greedily; speak each on its own line of
        # words so that one mnemonic is one word of output.
        ipa = []
        for i in range(0, len(phonemes), 40):
            ipa += speak(voice, phonemes[i:i + 40])
        result["tables"][name] = sorted(set(w.replace("ˈ", "").replace("ˌ", "") for w in ipa) - {""})
    result["texts_command"] = "espeak-ng -q --ipa -v LANG TEXT for each of TEXTS in tools/espeak_inventory.py"
    result["texts"] = {}
    for lang, text in TEXTS.items():
        res = subprocess.run(["espeak-ng", "-q", "--ipa", "-v", lang, text], capture_output=True, text=True,
                             timeout=60)
        result["texts"][lang] = " ".join(res.stdout.split())
    Path(argv[1]).write_text(json.dumps(result, ensure_ascii=False, indent=1) + "\n", encoding="utf-8")
    print(f"{len(result['tables'])} tables, {sum(map(len, result['tables'].values()))} IPA words -> {argv[1]}")


if __name__ == "__main__":
    main(sys.argv)
