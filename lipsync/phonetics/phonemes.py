"""Phone sets and phoneme-to-viseme maps, as data in ``configs/``.

* ``configs/phonesets/<name>.yaml`` — a canonical phone set plus the aliases that bring
  other notations into it (the shipped ``english`` set: ARPAbet, TIMIT, MFA English IPA).
* ``configs/maps/<name>.yaml`` — a :class:`PhonemeMap` (DESIGN.md's format): ``silence``
  and ``fallback`` visemes, ``map`` from phone to a viseme or a list of visemes (a list
  splits the phone's time evenly: diphthongs), optional ``closures`` (visemes that must be
  reached fully even when short), ``breath`` (the viseme of parted lips drawing breath
  before speech, which the ``dominance`` timing model shows ahead of speech after a
  pause), ``aliases`` (other names of each viseme, e.g. the Preston Blair names of
  Rhubarb's shapes) and ``phoneset``.

A label is looked up in this order: as written in ``map``; as a silence label (of the
phone set, case-insensitive); through the phone set to its canonical phone; upper-cased;
then, for any phone of any language, by the map's feature ``rules``
(:mod:`lipsync.phonetics.visemes`: the IPA segment's place, manner, rounding, height...).
A label none of these finds -- one that is not a phone at all -- goes to ``fallback`` with
one warning per label.

``rules`` in a map file is the name of a shipped rule set (``rhubarb``, ``oculus``), a
list of rows such as ``{place: bilabial, viseme: A}``, or ``none``. A map that does not
say uses the shipped rule set whose visemes it has (a map of Rhubarb's A-H gets
``rhubarb``), so maps written before rules existed keep working and gain every language.

:func:`map_timeline` reads a timeline's notation from all its labels
(:func:`lipsync.phonetics.detect`): in an IPA timeline ``y``, ``r`` and ``q`` are IPA's
rounded vowel, trill and uvular stop (not ARPAbet's glide, English r and TIMIT's glottal
stop); a pinyin timeline (``j``, ``ing1``, ``iii4``) is read as pinyin.

Examples
--------
>>> from lipsync.motion.timeline import Segment, Timeline
>>> pmap = load_map("english-to-rhubarb")
>>> tl = Timeline((Segment(0, .1, "sil"), Segment(.1, .2, "M"), Segment(.2, .4, "AY1")))
>>> [(s.label, round(s.end, 2)) for s in map_timeline(tl, pmap)]
[('X', 0.1), ('A', 0.2), ('D', 0.3), ('B', 0.4)]
"""

from __future__ import annotations

import functools
import unicodedata
import os
import re
import warnings
from pathlib import Path
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from .. import phonetics
from .._data import data_dir
from ..errors import MapError, TimelineError, UnknownNameError
from . import visemes as _rules
from .segments import parse_sequence as _parse_sequence
from ..registry import Registry
from ..motion.timeline import VISEME, Segment, Timeline

PathLike = Union[str, "os.PathLike[str]"]

DEFAULT_MAP = "english-to-rhubarb"
DEFAULT_PHONESET = "english"


_STRESS = re.compile(r"^[A-Za-z]+[0-2]$")


class UnknownLabelWarning(UserWarning):
    """A timeline label that the phoneme map does not know (shown once per label)."""


# --- phone sets ---------------------------------------------------------------------------


class PhoneSet(BaseModel):
    """A canonical phone set and the aliases that normalise other notations into it.

    Examples
    --------
    >>> ps = load_phoneset("english")
    >>> ps.normalise("ah"), ps.normalise("tʲ"), ps.normalise("iː"), ps.normalise("h#"), ps.normalise("??")
    ('AH', 'T', 'IY', '', None)
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    description: str = ""
    phones: Dict[str, str]
    silence: List[str] = Field(default_factory=list)
    aliases: Dict[str, str] = Field(default_factory=dict)
    strip_marks: List[str] = Field(default_factory=list)
    # ARPAbet stress digits (AH0, AY1) carry no mouth-shape information.
    strip_stress: bool = True

    @model_validator(mode="after")
    def _aliases_target_phones(self) -> "PhoneSet":
        bad = sorted({v for v in self.aliases.values() if v not in self.phones})
        if bad:
            raise ValueError(f"aliases point to phones not in the set: {', '.join(bad)}")
        return self

    @functools.cached_property
    def _silence_lower(self) -> frozenset:
        return frozenset(s.lower() for s in self.silence)

    def is_silence(self, label: str) -> bool:
        """True for labels that mean silence (case-insensitive)."""
        return label.strip().lower() in self._silence_lower

    def normalise(self, label: str) -> Optional[str]:
        """The canonical phone for ``label``, ``""`` for silence, or None if unknown."""
        label = label.strip()
        if self.is_silence(label):
            return ""
        for candidate in (label, label.upper()):
            if candidate in self.phones:
                return candidate
        for candidate in (label, label.lower()):
            if candidate in self.aliases:
                return self.aliases[candidate]
        if self.strip_stress and _STRESS.match(label):
            return self.normalise(label[:-1])
        stripped = label
        for mark in self.strip_marks:
            stripped = stripped.replace(mark, "")
        if self.strip_marks:
            # any other diacritic as well (ç̥, ɜ̯): a mark never makes a letter another phone;
            # precomposed letters (ç, ỹ) are one character in NFC and stay whole
            stripped = "".join(c for c in unicodedata.normalize("NFC", stripped) if not unicodedata.combining(c))
        if stripped != label and stripped:
            return self.normalise(stripped)
        return None


# --- maps ---------------------------------------------------------------------------------


class PhonemeMap(BaseModel):
    """A phoneme-to-viseme map (DESIGN.md's ``configs/maps/<name>.yaml`` format).

    Examples
    --------
    >>> m = PhonemeMap(name="tiny", silence="rest", fallback="open", map={"M": "closed", "AY": ["open", "wide"]})
    >>> m.targets("AY"), m.targets("sil"), m.visemes()
    (['open', 'wide'], ['rest'], ['closed', 'open', 'rest', 'wide'])
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    name: str
    description: str = ""
    silence: str
    fallback: str
    map: Dict[str, Union[str, List[str]]]
    closures: List[str] = Field(default_factory=list)
    breath: Optional[str] = None
    aliases: Dict[str, List[str]] = Field(default_factory=dict)
    phoneset: Optional[str] = DEFAULT_PHONESET
    # Feature rules for labels `map` lacks: a shipped rule set's name, rows, "none", or
    # None (the shipped rule set whose visemes the map has, if any).
    rules: Optional[Union[str, List[Dict[str, Any]]]] = None

    @field_validator("rules")
    @classmethod
    def _rules_valid(cls, v):
        if isinstance(v, str):
            if v != "none" and v not in _rules.RULESETS:
                raise ValueError(f"unknown rule set {v!r}; one of {', '.join(_rules.RULESETS)}, none, "
                                 f"or a list of rows")
        elif v is not None:
            _rules.compile_rules(v)
        return v

    @field_validator("silence", "fallback")
    @classmethod
    def _non_empty(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("must be a viseme name, not empty")
        return v.strip()

    @field_validator("map")
    @classmethod
    def _targets_non_empty(cls, v: Dict[str, Union[str, List[str]]]) -> Dict[str, Union[str, List[str]]]:
        for label, target in v.items():
            items = [target] if isinstance(target, str) else target
            if not items or any(not t.strip() for t in items):
                raise ValueError(f"phone {label!r} maps to no viseme")
        return v

    @model_validator(mode="after")
    def _closures_known(self) -> "PhonemeMap":
        known = set(self.visemes())
        bad = [c for c in self.closures if c not in known]
        if bad:
            raise ValueError(f"closures name visemes the map never uses: {', '.join(bad)}")
        if self.breath is not None and self.breath not in known:
            raise ValueError(f"breath names a viseme the map never uses: {self.breath}")
        bad = [v for v in self.aliases if v not in known]
        if bad:
            raise ValueError(f"aliases given for visemes the map never uses: {', '.join(bad)}")
        return self

    def _own_visemes(self) -> set:
        out = {self.silence, self.fallback}
        for target in self.map.values():
            out.update([target] if isinstance(target, str) else target)
        return out

    def visemes(self) -> List[str]:
        """Every viseme the map can produce (sorted), its rules' included."""
        return sorted(self._own_visemes() | set(_rules.rules_visemes(self._compiled_rules)))

    @functools.cached_property
    def _compiled_rules(self) -> tuple:
        """The feature rules in use (see the module docstring); () for none."""
        if self.rules == "none":
            return ()
        if isinstance(self.rules, str):
            return _rules.compiled(self.rules)
        if self.rules is not None:
            return _rules.compile_rules(self.rules)
        own = self._own_visemes()
        for name in _rules.RULESETS:
            rules = _rules.compiled(name)
            if set(_rules.rules_visemes(rules)) <= own:
                return rules
        return ()

    @functools.cached_property
    def _phoneset(self) -> Optional[PhoneSet]:
        return load_phoneset(self.phoneset) if self.phoneset else None

    def is_silence(self, label: str) -> bool:
        """True if ``label`` means silence for this map."""
        ps = self._phoneset
        if ps is not None:
            return ps.is_silence(label)
        return label.strip().lower() in _BUILTIN_SILENCE

    def targets(self, label: str, *, notation: Optional[str] = None) -> Optional[List[str]]:
        """The visemes for ``label`` (several for a split phone), or None if unknown.

        ``notation`` is the timeline's (:func:`lipsync.phonetics.detect`); None reads the
        label alone, as English first (``y`` is ARPAbet's glide), then as IPA.

        Examples
        --------
        >>> m = load_map("rhubarb")
        >>> m.targets("y"), m.targets("y", notation="ipa"), m.targets("ʁ"), m.targets("j", notation="pinyin")
        (['B'], ['F'], ['B'], ['B'])
        """
        if notation in _CONVERTED and not self.is_silence(label):
            ipa = phonetics.to_ipa(label, notation)
            parts = _parse_sequence(ipa) if ipa else None
            if parts and self._compiled_rules:  # X-SAMPA's R is ʁ even where the map has ARPAbet's R
                return _rules.parts_visemes(parts, self._compiled_rules)
            notation = None  # not of that notation, or no rules to read it by: the label alone
        if label in self.map:
            return _as_list(self.map[label])
        if self.is_silence(label):
            return [self.silence]
        if notation in (None, "english", "arpabet", "timit", "mfa") or (
                notation == "ipa" and _ipa_letters(label) not in _IPA_NOT_ENGLISH):
            english = self._english_targets(label)
            if english is not None or notation in ("english", "arpabet", "timit"):
                return english
            return self._feature_targets(label)
        return self._feature_targets(label)

    def _english_targets(self, label: str) -> Optional[List[str]]:
        ps = self._phoneset
        if ps is not None:
            canon = ps.normalise(label)
            if canon == "":
                return [self.silence]
            if canon is not None and canon in self.map:
                return _as_list(self.map[canon])
        if label.upper() in self.map:
            return _as_list(self.map[label.upper()])
        return None

    def _feature_targets(self, label: str) -> Optional[List[str]]:
        if not self._compiled_rules:
            return None
        return _rules.label_visemes(label, self._compiled_rules)

    def renamed(self, names: Mapping[str, str]) -> "PhonemeMap":
        """A copy with every viseme renamed through ``names`` (missing keys unchanged)."""
        r = lambda v: names.get(v, v)  # noqa: E731
        rules = _rules.renamed_rules(self._compiled_rules, names) if self._compiled_rules else "none"
        copy = self.model_copy(update=dict(
            rules=rules,
            silence=r(self.silence), fallback=r(self.fallback),
            map={k: (r(t) if isinstance(t, str) else [r(x) for x in t]) for k, t in self.map.items()},
            closures=[r(c) for c in self.closures],
            breath=None if self.breath is None else r(self.breath),
            aliases={r(k): v for k, v in self.aliases.items()}))
        copy.__dict__.pop("_compiled_rules", None)  # model_copy copies cached properties too
        return copy


# Used only by maps that name no phone set.
_BUILTIN_SILENCE = phonetics.SILENCE

# ASCII labels that are one sound in ARPAbet/TIMIT and another in IPA: read as IPA in a
# timeline whose notation is IPA (y: rounded vowel, not the glide; r: trill, not English r;
# q: uvular stop, not TIMIT's glottal stop).
_IPA_NOT_ENGLISH = frozenset({"y", "r", "q"})
# Marks that do not change which letter a label is: length (yː is long y, not ARPAbet Y),
# half-length, every combining diacritic (ỹ, y̯, r̥) and secondary articulations (rʲ, qʷ).
_NOT_LETTERS = frozenset("ːˑ:")


def _ipa_letters(label: str) -> str:
    """A label's letters without length marks and diacritics (``yː`` -> ``y``)."""
    import unicodedata

    from .segments import FEATURES, MODIFIERS

    text = unicodedata.normalize("NFD", label.strip())
    return "".join(c for c in text if c not in _NOT_LETTERS and not unicodedata.combining(c)
                   and (c in FEATURES or c not in MODIFIERS))   # ʲ ʷ ʰ: secondary marks, not letters


# Notations whose labels are converted into IPA before anything else is asked.
_CONVERTED = frozenset({"xsampa", "pinyin", "espeak"})


def _as_list(target: Union[str, List[str]]) -> List[str]:
    return [target] if isinstance(target, str) else list(target)


# --- loading ------------------------------------------------------------------------------


def _yaml_line(text: str, loc: Sequence[Union[str, int]]) -> Optional[int]:
    """1-based line of the YAML node at ``loc`` (pydantic's error location), if found."""
    import yaml

    try:
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError:
        return None
    line = None
    for key in loc:
        if node is None:
            break
        line = node.start_mark.line + 1
        nxt = None
        if isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                if k.value == str(key):
                    line, nxt = k.start_mark.line + 1, v
                    break
        elif isinstance(node, yaml.SequenceNode) and isinstance(key, int) and key < len(node.value):
            nxt = node.value[key]
            line = nxt.start_mark.line + 1
        node = nxt
    return line


def _load_yaml_model(model, path: Path, error):
    import yaml

    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error("no such file", path=path) from None
    except UnicodeDecodeError as exc:
        raise error(f"not UTF-8 text ({exc.reason})", path=path) from None
    except OSError as exc:
        raise error(f"cannot read: {exc.strerror or exc}", path=path) from None
    from .._yaml import safe_load

    try:
        data = safe_load(text)  # yaml.safe_load, but a key given twice is an error naming both lines
    except yaml.MarkedYAMLError as exc:
        # min(): the end-of-file mark can lie one line past the last (found by fuzzing).
        line = min(exc.problem_mark.line + 1, text.count("\n") + 1) if exc.problem_mark else None
        raise error(f"not valid YAML ({exc.problem})", path=path, line=line) from None
    except yaml.YAMLError as exc:
        raise error(f"not valid YAML ({exc})", path=path) from None
    except RecursionError:  # found by fuzzing: thousands of nested [ or { overflow PyYAML's recursion
        raise error("not valid YAML (nested too deeply)", path=path) from None
    except ValueError as exc:  # found by fuzzing: an integer of > 4300 digits (Python's int-from-text limit)
        raise error(f"not valid YAML ({str(exc)[:60]})", path=path) from None
    if not isinstance(data, dict):
        raise error("expected a YAML mapping (name:, silence:, map:, ...)", path=path, line=1)
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        loc = [p for p in first["loc"]]
        field = ".".join(str(p) for p in loc) or "(top level)"
        raise error(f"{field}: {first['msg']}", path=path, line=_yaml_line(text, loc)) from None


PHONESETS: Registry[Path] = Registry("phone set")
MAPS: Registry[Path] = Registry("phoneme map")


def _register_shipped() -> None:
    try:
        root = data_dir("configs")
    except FileNotFoundError:
        return
    for path in sorted((root / "phonesets").glob("*.yaml")):
        PHONESETS.register(path.stem, path)
    for path in sorted((root / "maps").glob("*.yaml")):
        # "english-to-rhubarb" is also reachable as "rhubarb"; maps from other label sets
        # (polly-to-rhubarb, azure-to-rhubarb) keep their full names, so the short name
        # always means the map from the default phone set.
        source, _, short = path.stem.partition("-to-")
        MAPS.register(path.stem, path, aliases=(short,) if short and source == DEFAULT_PHONESET else ())


_register_shipped()


@functools.lru_cache(maxsize=None)
def load_phoneset(name: str) -> PhoneSet:
    """A shipped phone set by name (``configs/phonesets/<name>.yaml``)."""
    return _load_yaml_model(PhoneSet, PHONESETS.get(name), MapError)


def load_map(name_or_path: Union[str, PathLike, None] = None) -> PhonemeMap:
    """Load a shipped map by name or any map file by path.

    Parameters
    ----------
    name_or_path : str or path-like, optional
        A name from ``MAPS.names()`` (or its short alias such as ``rhubarb``), or a YAML file
        in DESIGN.md's map format. Default: ``english-to-rhubarb``.

    Raises
    ------
    MapError
        The file is not a valid map (message names the file, line and field).
    UnknownNameError
        Not a shipped name and not an existing file.

    Examples
    --------
    >>> load_map("oculus").targets("p")
    ['PP']
    """
    if name_or_path is None:
        name_or_path = DEFAULT_MAP
    text = os.fspath(name_or_path)
    if text in MAPS:
        path = MAPS.get(text)
    elif os.path.exists(text) or text.endswith((".yaml", ".yml")) or os.sep in text:
        path = Path(text)
    else:
        raise UnknownNameError(f"unknown phoneme map {text!r}: not a file; shipped maps: {', '.join(MAPS.names())}")
    pmap = _load_yaml_model(PhonemeMap, path, MapError)
    if pmap.phoneset is not None and pmap.phoneset not in PHONESETS:
        raise MapError(f"phoneset {pmap.phoneset!r} is not shipped; valid: {', '.join(PHONESETS.names())}",
                       path=path, line=_yaml_line(path.read_text(encoding="utf-8"), ["phoneset"]))
    return pmap


# --- mapping ------------------------------------------------------------------------------


def map_timeline(timeline: Timeline, pmap: PhonemeMap, *, rest: Optional[str] = None,
                 notation: Optional[str] = None) -> Timeline:
    """Phoneme timeline -> viseme timeline.

    Silence labels, and gaps (time with no segment, up to the file's stated end), become
    ``rest`` if given, else ``pmap.silence``, so the result covers the whole file. A phone mapped to several visemes has its time split
    evenly among them. Unknown labels map to ``pmap.fallback``, with one
    :class:`UnknownLabelWarning` per distinct label. A viseme timeline is returned unchanged.
    ``notation`` (``ipa``, ``english``, ``pinyin``, ``xsampa``, ``espeak``; see
    :data:`lipsync.phonetics.NOTATIONS`) is detected from the labels when not given.

    Examples
    --------
    >>> import warnings
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = Timeline((Segment(0, .1, "pau"), Segment(.1, .2, "zzz")))
    >>> with warnings.catch_warnings(record=True) as w:
    ...     warnings.simplefilter("always")
    ...     out = map_timeline(tl, load_map("rhubarb"), rest="rest")
    >>> out.labels(), len(w)
    (['rest', 'C'], 1)
    """
    if timeline.kind == VISEME:
        return timeline
    if notation is None:
        notation = phonetics.detect(s.label for s in timeline)
    cache: Dict[str, List[str]] = {}
    unknown: List[str] = []
    segments: List[Segment] = []
    silence = rest if rest is not None else pmap.silence
    t = 0.0
    for seg in timeline:
        if seg.start > t:  # a gap is silence
            segments.append(Segment(t, seg.start, silence))
        t = seg.end
        targets = cache.get(seg.label)
        if targets is None:
            if seg.label not in pmap.map and pmap.is_silence(seg.label):
                targets = [silence]
            else:
                targets = pmap.targets(seg.label, notation=notation)
                if targets is None:
                    unknown.append(seg.label)
                    targets = [pmap.fallback]
            cache[seg.label] = targets
        step = (seg.end - seg.start) / len(targets)
        for i, v in enumerate(targets):
            end = seg.end if i == len(targets) - 1 else seg.start + (i + 1) * step
            segments.append(Segment(seg.start + i * step, end, v))
    if timeline.stated_end is not None and timeline.stated_end > t:
        segments.append(Segment(t, float(timeline.stated_end), silence))
    for label in unknown:
        warnings.warn(f"{timeline.path or 'timeline'}: label {label!r} is not in map {pmap.name!r}; "
                      f"showing fallback viseme {pmap.fallback!r}", UnknownLabelWarning, stacklevel=2)
    return Timeline(tuple(segments), kind=VISEME, path=timeline.path, stated_end=timeline.stated_end)


def unknown_labels(timeline: Timeline, pmap: PhonemeMap, *, notation: Optional[str] = None) -> List[str]:
    """Distinct labels of a phoneme timeline that ``pmap`` does not know, in order of appearance."""
    if timeline.kind == VISEME:
        return []
    if notation is None:
        notation = phonetics.detect(s.label for s in timeline)
    seen: Dict[str, None] = {}
    for seg in timeline:
        if (seg.label not in seen and not pmap.is_silence(seg.label)
                and pmap.targets(seg.label, notation=notation) is None):
            seen[seg.label] = None
    return list(seen)


# --- viseme names: map <-> bank -----------------------------------------------------------


def resolve_visemes(pmap: PhonemeMap, viseme_names: Iterable[str]) -> Tuple[Dict[str, str], List[str]]:
    """Match the map's visemes to a bank's viseme names.

    Returns ``(names, missing)``: ``names`` maps each map viseme to the bank's name for it;
    ``missing`` lists map visemes the bank has under no name. If the bank has every viseme
    under the map's own names they are used; otherwise, if it has every one under an alias
    (e.g. the Preston Blair names), the aliases are used, so that an alias equal to another
    viseme's own name (Preston Blair "E" is Rhubarb's C, not its E) resolves consistently.

    Examples
    --------
    >>> pb = ["MBP", "etc", "E", "AI", "O", "U", "FV", "L", "rest"]
    >>> names, missing = resolve_visemes(load_map("rhubarb"), pb)
    >>> names["C"], names["E"], names["X"], missing
    ('E', 'O', 'rest', [])
    """
    bank = list(viseme_names)
    bank_set = set(bank)
    lower = {n.lower(): n for n in bank}
    wanted = pmap.visemes()
    if all(v in bank_set for v in wanted):
        return {v: v for v in wanted}, []

    def via_alias(v: str) -> Optional[str]:
        for alias in pmap.aliases.get(v, []):
            if alias in bank_set:
                return alias
            if alias.lower() in lower:
                return lower[alias.lower()]
        return None

    by_alias = {v: via_alias(v) for v in wanted}
    if all(by_alias.values()):
        return dict(by_alias), []  # type: ignore[arg-type]
    names, missing = {}, []
    for v in wanted:
        if v in bank_set:
            names[v] = v
        elif by_alias[v]:
            names[v] = by_alias[v]
        else:
            missing.append(v)
    return names, missing


def check_map_against(pmap: PhonemeMap, viseme_names: Iterable[str], *, path: Optional[PathLike] = None) -> Dict[str, str]:
    """Raise MapError if ``pmap`` targets a viseme the bank lacks; return the name matching.

    Examples
    --------
    >>> check_map_against(load_map("oculus"), ["sil", "PP"])
    Traceback (most recent call last):
    ...
    lipsync.errors.MapError: map 'english-to-oculus' uses visemes the bank lacks: CH, DD, E, FF, I, O, RR, SS, TH, U, aa, kk, nn (bank has: PP, sil)
    """
    bank = list(viseme_names)
    names, missing = resolve_visemes(pmap, bank)
    if missing:
        raise MapError(f"map {pmap.name!r} uses visemes the bank lacks: {', '.join(missing)} "
                       f"(bank has: {', '.join(sorted(bank))})", path=path)
    return names


def canonical_viseme_timeline(timeline: Timeline, pmap: PhonemeMap) -> Timeline:
    """A viseme timeline's labels in the map's own viseme names (aliases translated).

    Used for files that are already visemes (Rhubarb, Moho): Papagayo writes the Preston
    Blair names (MBP, etc, AI, ..., rest), Rhubarb writes A-H and X. If every label is one of
    the map's own names they are kept; otherwise labels are read as aliases where they are one.

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = Timeline((Segment(0, 1, "rest"), Segment(1, 2, "E"), Segment(2, 3, "MBP")), kind="viseme")
    >>> canonical_viseme_timeline(tl, load_map("rhubarb")).labels()
    ['X', 'C', 'A']
    """
    own = set(pmap.visemes())
    labels = {s.label for s in timeline}
    if labels <= own:
        return timeline
    reverse: Dict[str, str] = {}
    for v, aliases in pmap.aliases.items():
        for a in aliases:
            reverse.setdefault(a.lower(), v)
    segs = tuple(Segment(s.start, s.end, reverse.get(s.label.lower(), s.label)) for s in timeline)
    return timeline.replace(segments=segs)


def bank_viseme_timeline(timeline: Timeline, pmap: PhonemeMap, viseme_names: Optional[Iterable[str]] = None, *,
                         rest: Optional[str] = None, map_path: Optional[PathLike] = None
                         ) -> Tuple[Timeline, PhonemeMap]:
    """Map any timeline to a bank's visemes: the one place phoneme and viseme files meet a bank.

    Phoneme timelines go through the map; viseme timelines (Rhubarb, Moho) have their
    labels translated to the map's own names (:func:`canonical_viseme_timeline`). With
    ``viseme_names`` the map's visemes are matched to the bank's (through aliases, e.g.
    Preston Blair names) and the map is renamed to them.

    Parameters
    ----------
    timeline : Timeline
        As read by :func:`lipsync.readers.read_timeline`.
    pmap : PhonemeMap
        The phoneme-to-viseme map.
    viseme_names : iterable of str, optional
        The bank's visemes; a map viseme or timeline viseme the bank lacks is an error.
    rest : str, optional
        The viseme for silence and gaps (default: the map's silence viseme).
    map_path : path-like, optional
        The map's file, named in errors.

    Returns
    -------
    (Timeline, PhonemeMap)
        The viseme timeline covering the whole file, and the map in the bank's names (its
        ``closures`` are what :func:`lipsync.motion.sequencer.sequence` wants).

    Examples
    --------
    >>> from lipsync.motion.timeline import Segment, Timeline
    >>> tl = Timeline((Segment(0, 0.2, "M"), Segment(0.2, 0.5, "AA")), kind="phoneme")
    >>> vt, m = bank_viseme_timeline(tl, load_map("rhubarb"), "ABCDEFGHX", rest="X")
    >>> vt.labels(), m.closures
    (['A', 'D'], ['A'])
    """
    if timeline.kind == VISEME:
        timeline = canonical_viseme_timeline(timeline, pmap)
    if viseme_names is not None:
        bank = list(viseme_names)
        names = check_map_against(pmap, bank, path=map_path)
        pmap = pmap.renamed(names)
        if timeline.kind == VISEME:
            timeline = timeline.replace(segments=tuple(
                Segment(s.start, s.end, names.get(s.label, s.label)) for s in timeline))
            unknown = sorted({s.label for s in timeline} - set(bank))
            if unknown:
                raise TimelineError(f"visemes not in the bank: {', '.join(unknown)}", path=timeline.path)
    return map_timeline(timeline, pmap, rest=rest), pmap
