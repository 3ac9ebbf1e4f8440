"""YAML as ``yaml.safe_load`` reads it, except that a key given twice in one mapping is an error.

PyYAML keeps the last of two equal keys without a word, so ``{AA: D, AA: B}`` in a phoneme
map, or a viseme or a control line named twice in bank.yaml, silently lost one of them and
``lipsync check`` said OK. The loaders here are PyYAML's safe loaders (pure Python, and
libyaml's C parser where PyYAML has it) with one change: before a mapping is built, its
keys are compared, and a repeated one raises :class:`DuplicateKeyError` -- a
``yaml.MarkedYAMLError`` whose mark is the second occurrence and whose message names the
key and both lines, so every caller's existing YAML error handling reports it with the
file and line. Everything else is ``safe_load``'s: same tags, same types, merge keys
(``<<``) still let later keys override merged ones.

Examples
--------
>>> safe_load("a: 1\\nb: [2, 3]\\n")
{'a': 1, 'b': [2, 3]}
>>> try:
...     safe_load("map:\\n  AA: D\\n  AA: B\\n")
... except DuplicateKeyError as exc:
...     print(exc.problem, "| line", exc.problem_mark.line + 1)
duplicate key 'AA' (lines 2 and 3; YAML would keep only the last) | line 3
"""

from __future__ import annotations

from typing import Any

import yaml

_MERGE_TAG = "tag:yaml.org,2002:merge"


class DuplicateKeyError(yaml.constructor.ConstructorError):
    """A mapping key given twice; ``problem_mark`` is the second occurrence."""


class _UniqueKeys:
    """Mixin for a SafeConstructor-based loader: refuse a mapping with a repeated key."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = {}
            for key_node, _ in node.value:
                if key_node.tag == _MERGE_TAG:
                    continue
                key = self.construct_object(key_node, deep=True)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:  # an unhashable key: safe_load's own error follows
                    continue
                if first is not key_node:
                    a, b = first.start_mark.line + 1, key_node.start_mark.line + 1
                    where = f"lines {a} and {b}" if a != b else f"line {a}, twice"
                    raise DuplicateKeyError(
                        "while constructing a mapping", node.start_mark,
                        f"duplicate key {key!r} ({where}; YAML would keep only the last)", key_node.start_mark)
        return super().construct_mapping(node, deep=deep)


class SafeLoader(_UniqueKeys, yaml.SafeLoader):
    """``yaml.SafeLoader`` refusing duplicate keys."""


#: libyaml's parser (about ten times faster) when PyYAML was built with it, else None.
CSafeLoader = (type("CSafeLoader", (_UniqueKeys, yaml.CSafeLoader),
                    {"__doc__": "``yaml.CSafeLoader`` refusing duplicate keys."})
               if hasattr(yaml, "CSafeLoader") else None)


def safe_load(text: str) -> Any:
    """``yaml.safe_load(text)`` (the pure-Python loader, as it uses), refusing duplicate keys.

    Not libyaml: its parser recurses on the C stack and crashes on deeply nested text
    (lipsync.banks.bank sends only shallow text to :data:`CSafeLoader`).
    """
    return yaml.load(text, Loader=SafeLoader)
