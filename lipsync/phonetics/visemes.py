"""Viseme maps defined on features: which mouth each kind of sound shows.

A rule set is an ordered table of rows; each row names conditions on a segment (its letter,
or its features: ``kind place manner voiced height backness rounded nasal lateral rhotic
airstream``) and the viseme it shows. The first row whose conditions all hold decides.
A condition's value is one value or a list of values (any of them). Rows that name
``phones`` are the explicit per-phone rows, for sounds whose mouth the features alone do
not give (English ``ɹ`` rounds the lips; an alveolar trill does not).

A label is shown as one viseme per part (:func:`label_visemes`): a diphthong or an
affricate splits its time between its parts' shapes; repeated shapes merge (``ts`` is one
B); length keeps one shape (``aː`` is one D); tone and stress are dropped.

The shipped rule sets, :data:`RULESETS`: ``rhubarb`` (Rhubarb Lip Sync's A-H and X) and
``oculus`` (the 15 Oculus/Meta visemes). Both agree with ``configs/maps/english-to-*.yaml``
on every English phone (the tests check it), so English written in IPA gives the same
mouth as English written in ARPAbet.

Examples
--------
>>> label_visemes("œ̃", "rhubarb"), label_visemes("aʊ", "rhubarb"), label_visemes("ɥ", "oculus")
(['E'], ['D', 'F'], ['U'])
>>> label_visemes("zz", "rhubarb") is None
True
"""

from __future__ import annotations

import functools
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from .features import BACKNESS, HEIGHTS, MANNERS, PLACES, Features
from .segments import Part, parse, parse_sequence, split

CONDITION_KEYS = ("phones", "kind", "place", "manner", "voiced", "height", "backness", "rounded", "nasal",
                  "lateral", "rhotic", "airstream")
_ALLOWED: Dict[str, Tuple[Any, ...]] = {
    "kind": ("consonant", "vowel"), "place": PLACES, "manner": MANNERS, "height": HEIGHTS,
    "backness": BACKNESS, "voiced": (True, False), "rounded": (True, False), "nasal": (True, False),
    "lateral": (True, False), "rhotic": (True, False), "airstream": ("pulmonic", "click", "implosive", "ejective"),
}

Rule = Tuple[Tuple[Tuple[str, frozenset], ...], str]


def _fields(*rows) -> List[Dict[str, Any]]:
    return [dict(r) for r in rows]


# --- Rhubarb Lip Sync: A closed, B teeth together, C open, D wide, E rounded, F puckered,
#     G lip on teeth, H tongue up, X rest ------------------------------------------------
RHUBARB_RULES: List[Dict[str, Any]] = [
    # Explicit per-phone rows first (the features alone would say otherwise).
    dict(phones=["ɹ", "ɻ", "ɚ", "ɝ"], viseme="E",
         why="English-type r (and r-coloured vowels) is made with rounded, protruded lips: "
             "english-to-rhubarb maps R and ER to E"),
    dict(rhotic=True, viseme="E", why="any vowel written r-coloured (˞) is ER's shape"),
    # Lips
    dict(kind="consonant", place="bilabial", viseme="A",
         why="both lips meet (p b m, ɓ, ʘ) or nearly meet (ɸ β, Japanese fu, Spanish b between vowels)"),
    dict(kind="consonant", place="labiodental", viseme="G", why="lower lip on the upper teeth (f v ɱ ʋ)"),
    dict(kind="consonant", place=["labial-velar", "labial-palatal"], viseme="F",
         why="w ʍ ɥ: the lips pucker as for u/y"),
    # Tongue tip raised behind the teeth
    dict(kind="consonant", lateral=True, viseme="H", why="l-sounds: tongue tip up, seen through parted lips (l ɫ ʎ ɬ ɭ)"),
    # No oral gesture: the mouth takes the neighbouring vowel's shape; open is the best guess
    dict(kind="consonant", place=["glottal", "pharyngeal", "epiglottal"], viseme="C",
         why="h ʔ ħ ʕ: made in the throat, the mouth stays as the vowel has it (HH and Q are C)"),
    dict(kind="consonant", viseme="B",
         why="every other consonant (tongue tip, blade or body): jaw nearly closed, teeth together"),
    # Vowels: rounding picks the rounded shapes, openness C or D
    dict(kind="vowel", rounded=True, height=["close", "near-close"], viseme="F",
         why="close rounded vowels pucker the lips (u y ʉ ʊ ʏ: UW and UH are F)"),
    dict(kind="vowel", rounded=True, viseme="E",
         why="mid and open rounded vowels round without puckering (o ø ɔ œ ɒ ɶ: AO is E)"),
    dict(kind="vowel", height=["close", "near-close"], viseme="B",
         why="close unrounded vowels: spread lips, teeth close (i ɪ ɨ ɯ: IY and IH are B)"),
    dict(kind="vowel", height="open", viseme="D", why="open vowels: jaw wide open (a ɑ: AA is D)"),
    dict(kind="vowel", viseme="C", why="mid and near-open unrounded vowels: open (e ɛ ə æ ɐ ʌ: EH AE AH are C)"),
]

# --- Oculus (Meta) Lipsync: sil PP FF TH DD kk CH SS nn RR aa E I O U --------------------
OCULUS_RULES: List[Dict[str, Any]] = [
    dict(phones=["ɹ", "ɻ", "ɚ", "ɝ", "r", "ʀ"], viseme="RR", why="r-sounds and r-coloured vowels: the RR viseme (R, ER)"),
    dict(rhotic=True, viseme="RR", why="any vowel written r-coloured (˞)"),
    dict(kind="consonant", place="bilabial", viseme="PP", why="lips meet (P B M)"),
    dict(kind="consonant", place="labiodental", viseme="FF", why="lip on teeth (F V)"),
    dict(kind="consonant", place=["labial-velar", "labial-palatal"], viseme="U", why="w ʍ ɥ: puckered, as W is U"),
    dict(kind="consonant", place="dental", manner=["fricative", "approximant"], viseme="TH",
         why="tongue between the teeth (θ ð: TH DH)"),
    dict(kind="consonant", manner="nasal", place=["velar", "uvular"], viseme="kk", why="back nasals (NG is kk)"),
    dict(kind="consonant", manner="nasal", viseme="nn", why="other nasals: tongue up, lips apart (N)"),
    dict(kind="consonant", lateral=True, viseme="nn", why="l-sounds show as nn (L is nn)"),
    dict(kind="consonant", place=["glottal", "pharyngeal", "epiglottal"], viseme="E",
         why="no oral gesture: a neutral half-open mouth (HH and Q are E)"),
    dict(kind="consonant", place=["postalveolar", "retroflex", "alveolo-palatal", "palatal-velar"],
         manner="fricative", viseme="CH",
         why="tongue blade behind the ridge, lips slightly forward (SH ZH, the release of CH JH; ɕ ʂ ʐ ɧ)"),
    dict(kind="consonant", place="alveolar", manner="fricative", viseme="SS", why="s z"),
    dict(kind="consonant", place="palatal", manner="approximant", viseme="I", why="j: the i-shape (Y is I)"),
    dict(kind="consonant", place="palatal", manner="fricative", viseme="CH", why="ç ʝ: blade and body at the palate"),
    dict(kind="consonant", place=["palatal", "velar", "uvular"], viseme="kk",
         why="tongue body up at the back (K G; c ɟ x ɣ q ʁ χ)"),
    dict(kind="consonant", viseme="DD",
         why="tongue tip at the teeth or ridge (T D, flaps, trills, clicks)"),
    dict(kind="vowel", rounded=True, height=["close", "near-close"], viseme="U", why="u y ʉ ʊ ʏ (UW UH)"),
    dict(kind="vowel", rounded=True, viseme="O", why="o ø ɔ œ ɒ (AO)"),
    dict(kind="vowel", height=["close", "near-close"], viseme="I", why="i ɪ ɨ ɯ (IY IH)"),
    dict(kind="vowel", height=["close-mid", "open-mid"], backness=["front", "central"], viseme="E",
         why="e ɛ ɘ ɜ (EH is E)"),
    dict(kind="vowel", height="close-mid", viseme="E", why="ɤ: half-open, unrounded"),
    dict(kind="vowel", viseme="aa", why="schwa, ʌ and the open vowels (AH AA AE are aa)"),
]

RULESETS: Dict[str, List[Dict[str, Any]]] = {"rhubarb": RHUBARB_RULES, "oculus": OCULUS_RULES}


def compile_rules(rows: Iterable[Mapping[str, Any]]) -> Tuple[Rule, ...]:
    """Check rule rows (as written in Python or YAML) and make them fast to match.

    Raises
    ------
    ValueError
        A row without ``viseme``, a condition that is not a feature, or a value the
        feature cannot take (the message names the row, from 1, and the key).

    Examples
    --------
    >>> compile_rules([{"place": "bilabial", "viseme": "shut"}])[0][1]
    'shut'
    >>> compile_rules([{"place": "lips", "viseme": "shut"}])
    Traceback (most recent call last):
    ...
    ValueError: rule 1: place 'lips' is not one of bilabial, labiodental, ...
    """
    out = []
    for i, row in enumerate(rows, 1):
        if not isinstance(row, Mapping):
            raise ValueError(f"rule {i}: expected a mapping such as {{place: bilabial, viseme: A}}")
        viseme = row.get("viseme")
        if not isinstance(viseme, str) or not viseme.strip():
            raise ValueError(f"rule {i}: needs a viseme")
        conds = []
        for key, value in row.items():
            if key in ("viseme", "why"):
                continue
            if key not in CONDITION_KEYS:
                raise ValueError(f"rule {i}: {key!r} is not a feature; use one of {', '.join(CONDITION_KEYS)}")
            values = list(value) if isinstance(value, (list, tuple)) else [value]
            if key == "phones":
                values = [str(v) for v in values]
            else:
                allowed = _ALLOWED[key]
                for v in values:
                    if v not in allowed:
                        listing = ", ".join(str(a).lower() for a in allowed[:3]) + (", ..." if len(allowed) > 3 else "")
                        raise ValueError(f"rule {i}: {key} {v!r} is not one of {listing}")
            conds.append((key, frozenset(values)))
        out.append((tuple(conds), viseme.strip()))
    return tuple(out)


def _matches(conds, part: Part) -> bool:
    f: Features = part.features
    for key, values in conds:
        got = part.base if key == "phones" else getattr(f, key)
        if got not in values:
            return False
    return True


def part_viseme(part: Part, rules: Sequence[Rule]) -> Optional[str]:
    """The viseme of one part: the first rule that matches, or None.

    Examples
    --------
    >>> part_viseme(parse("ɸ").parts[0], compiled("rhubarb"))
    'A'
    """
    for conds, viseme in rules:
        if _matches(conds, part):
            return viseme
    return None


def parts_visemes(parts: Sequence[Part], rules: Sequence[Rule]) -> Optional[List[str]]:
    """One viseme per part, repeated neighbours merged; None if any part matches no rule.

    Examples
    --------
    >>> parts_visemes(parse("ts").parts, compiled("rhubarb")), parts_visemes(parse("pf").parts, compiled("rhubarb"))
    (['B'], ['A', 'G'])
    """
    out: List[str] = []
    for part in parts:
        v = part_viseme(part, rules)
        if v is None:
            return None
        if not out or out[-1] != v:
            out.append(v)
    return out


@functools.lru_cache(maxsize=None)
def compiled(name: str) -> Tuple[Rule, ...]:
    """A shipped rule set, compiled (``"rhubarb"`` or ``"oculus"``).

    Examples
    --------
    >>> len(compiled("rhubarb")) == len(RHUBARB_RULES)
    True
    """
    return compile_rules(RULESETS[name])


def rules_visemes(rules: Sequence[Rule]) -> List[str]:
    """Every viseme the rules can give (sorted)."""
    return sorted({v for _, v in rules})


def label_visemes(label: str, rules: Union[str, Sequence[Rule]] = "rhubarb") -> Optional[List[str]]:
    """The visemes of one IPA label (several for a diphthong or affricate), or None if not IPA.

    Examples
    --------
    >>> label_visemes("y"), label_visemes("eː"), label_visemes("t͡ʃ", "oculus"), label_visemes("a˥˩")
    (['F'], ['C'], ['DD', 'CH'], ['D'])
    """
    text = label.strip()
    # A secondary-articulation mark on its own (MFA and espeak sometimes split ``tʲ`` into
    # ``t`` + ``ʲ``) is the sound it is the superscript of: ʲ is a j-like glide, ʷ a w.
    text = BARE_MODIFIERS.get(text, text)
    phone = parse(text)
    parts = phone.parts if phone is not None else _r_coloured(text)
    if not parts:
        return None
    return parts_visemes(parts, compiled(rules) if isinstance(rules, str) else rules)


#: The r of espeak's r-coloured vowels written in one label (``ɑːɹ``, ``ɔːɹ``, ``ɪɹ``).
R_COLOURING = frozenset("ɹɻ")


def _r_coloured(text: str):
    """A vowel and its r colouring in one label: the two parts, each its own viseme (as a
    diphthong's halves are); None for any other run of sounds (``zz`` is not a phone)."""
    parts = parse_sequence(text)
    if parts and len(parts) == 2 and parts[0].features.kind == "vowel" and parts[1].base in R_COLOURING:
        return parts
    return None


#: Modifier letters read as a label of their own: the sound each is the superscript of.
BARE_MODIFIERS: Dict[str, str] = {
    "ʲ": "j", "ʷ": "w", "ᶣ": "ɥ", "ˠ": "ɣ", "ˤ": "ʕ", "ʰ": "h", "ʱ": "ɦ", "ⁿ": "n", "ˡ": "l", "ᵐ": "m",
    "ᵑ": "ŋ", "ᶮ": "ɲ",
}


def ipa_visemes(transcription: str, rules: Union[str, Sequence[Rule]] = "rhubarb") -> List[Tuple[str, List[str]]]:
    """Each segment of an IPA transcription with its visemes (for a G2P's output).

    Parameters
    ----------
    transcription : str
        IPA as espeak-ng (``--ipa``) or a dictionary writes it; stress, tone and boundaries
        are dropped (:func:`lipsync.phonetics.segments.split`).
    rules : str or compiled rules
        ``"rhubarb"``, ``"oculus"`` or the result of :func:`compile_rules`.

    Examples
    --------
    >>> ipa_visemes("bɔ̃ʒˈuʁ")
    [('b', ['A']), ('ɔ̃', ['E']), ('ʒ', ['B']), ('u', ['F']), ('ʁ', ['B'])]
    """
    rules = compiled(rules) if isinstance(rules, str) else rules
    out = []
    for seg in split(transcription):
        parts = parse_sequence(seg)
        vis = parts_visemes(parts, rules) if parts else None
        out.append((seg, vis if vis is not None else []))
    return out


def renamed_rules(rules: Sequence[Rule], names: Mapping[str, str]) -> List[Dict[str, Any]]:
    """Rules as rows with every viseme renamed through ``names`` (for a bank's own names).

    Examples
    --------
    >>> renamed_rules(compile_rules([{"place": "bilabial", "viseme": "A"}]), {"A": "MBP"})
    [{'place': ['bilabial'], 'viseme': 'MBP'}]
    """
    return [dict({k: sorted(v, key=str) for k, v in conds}, viseme=names.get(v, v)) for conds, v in rules]
