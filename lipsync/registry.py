"""One registry per pluggable part (timeline readers, phoneme maps, timing curves, encoders).

Lookup order follows imageio's plugin registry: an explicit name first, then a file
extension. Unknown names raise :class:`~lipsync.errors.UnknownNameError` listing the valid
ones, and the CLI takes its ``choices`` from :meth:`Registry.names`, so the two never drift.
"""

from __future__ import annotations

from typing import Callable, Dict, Generic, Iterable, List, Optional, Tuple, TypeVar

from .errors import UnknownNameError

T = TypeVar("T")


class Registry(Generic[T]):
    """A named collection of interchangeable implementations.

    Parameters
    ----------
    kind : str
        What the entries are, for error messages ("timeline format", "timing curve").

    Examples
    --------
    >>> curves = Registry("timing curve")
    >>> _ = curves.register("linear", lambda t: t)
    >>> curves.get("linear")(0.25)
    0.25
    >>> curves.names()
    ['linear']
    """

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: Dict[str, T] = {}
        self._extensions: Dict[str, str] = {}
        self._aliases: Dict[str, str] = {}

    def register(self, name: str, obj: T, *, extensions: Iterable[str] = (), aliases: Iterable[str] = ()) -> T:
        """Add ``obj`` under ``name`` (and optional file ``extensions`` like ``".phn"``)."""
        key = name.lower()
        if key in self._entries:
            raise ValueError(f"{self.kind} {name!r} is registered twice")
        self._entries[key] = obj
        for ext in extensions:
            self._extensions.setdefault(ext.lower(), key)
        for alias in aliases:
            self._aliases[alias.lower()] = key
        return obj

    def decorator(self, name: str, **kwargs) -> Callable[[T], T]:
        """Register the decorated object under ``name``."""

        def wrap(obj: T) -> T:
            return self.register(name, obj, **kwargs)

        return wrap

    def names(self) -> List[str]:
        """The registered names, in registration order."""
        return list(self._entries)

    def __contains__(self, name: object) -> bool:
        return isinstance(name, str) and self._resolve(name) is not None

    def _resolve(self, name: str) -> Optional[str]:
        key = name.lower()
        if key in self._entries:
            return key
        return self._aliases.get(key)

    def get(self, name: str) -> T:
        """The entry called ``name`` (case-insensitive); raises listing the valid names."""
        key = self._resolve(name)
        if key is None:
            raise UnknownNameError(
                f"unknown {self.kind} {name!r}; valid: {', '.join(self.names())}"
            )
        return self._entries[key]

    def canonical(self, name: str) -> str:
        """The registered name ``name`` (any case, or an alias) stands for; raises like :meth:`get`.

        Examples
        --------
        >>> r = Registry("thing")
        >>> _ = r.register("one", 1, aliases=("uno",))
        >>> r.canonical("UNO")
        'one'
        """
        self.get(name)
        return self._resolve(name)  # type: ignore[return-value]

    def name_for_extension(self, ext: str) -> Optional[str]:
        """The name registered for a file extension (with dot, any case), or None."""
        return self._extensions.get(ext.lower())

    def items(self) -> List[Tuple[str, T]]:
        return list(self._entries.items())

    def extensions(self) -> Dict[str, List[str]]:
        """Each name's registered extensions (sorted), for names that have any."""
        out: Dict[str, List[str]] = {}
        for ext, key in sorted(self._extensions.items()):
            out.setdefault(key, []).append(ext)
        return out
