"""TOML configuration files with errors that point at the line.

:mod:`tomllib` parses but forgets where a value came from. :class:`TomlFile`
keeps the text so that a bad or unknown key can be reported as
``machine.toml, line 12: unknown key 'kpp' in [axes.x]; expected one of ...``.
"""

import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

from .exceptions import ConfigError

__all__ = ["FORMAT_DOC", "TomlFile"]

#: Where messages send a user for the keys of every file.
FORMAT_DOC = "README.md, section 'File format'"

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*("[^"]*"|'[^']*'|[A-Za-z0-9_\-]+(?:\s*\.\s*[A-Za-z0-9_\-]+)*)\s*=""")


def _split_key(text):
    return tuple(part.strip().strip("\"'") for part in text.split("."))


@dataclass(frozen=True)
class TomlFile:
    """A parsed TOML file that remembers its text.

    Parameters
    ----------
    source : str
        File name used in messages.
    text : str
        The file's contents.
    """

    source: str
    text: str

    def __post_init__(self):
        try:
            data = tomllib.loads(self.text)
        except tomllib.TOMLDecodeError as exc:
            line = re.search(r"line (\d+)", str(exc))
            raise ConfigError(f"not valid TOML: {exc}", self.source, int(line.group(1)) if line else None) from None
        object.__setattr__(self, "data", data)

    @classmethod
    def read(cls, path):
        """Read and parse the TOML file at `path`."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise ConfigError(f"cannot read the file: {exc.strerror}", str(path)) from None
        return cls(str(path), text)

    def line_of(self, *keys):
        """1-based line that defines the key path `keys`, or ``None``.

        `keys` walks tables by name and arrays of tables by index, e.g.
        ``line_of("body", 2, "joint")`` is the ``joint =`` line of the third
        ``[[body]]``. When the last key is not written on a line of its own
        (inline tables), the line of the closest enclosing key is returned.
        """
        best = None
        table = ()
        counts = {}
        for number, line in enumerate(self.text.splitlines(), start=1):
            header = _HEADER.match(line)
            if header:
                path = _split_key(header.group(2))
                if header.group(1) == "[[":
                    counts[path] = counts.get(path, -1) + 1
                table = self._indexed(path, counts)
                if table == keys[: len(table)] and (best is None or len(table) > best[0]):
                    best = (len(table), number)
                continue
            key = _KEY.match(line)
            if key:
                full = table + _split_key(key.group(1))
                if full == keys[: len(full)] and (best is None or len(full) > best[0]):
                    best = (len(full), number)
        return None if best is None else best[1]

    @staticmethod
    def _indexed(path, counts):
        """Insert array-of-tables indices into a header path."""
        out = ()
        for i in range(1, len(path) + 1):
            out += (path[i - 1],)
            if path[:i] in counts:
                out += (counts[path[:i]],)
        return out

    def error(self, message, *keys):
        """A :class:`ConfigError` for `message` located at key path `keys`."""
        return ConfigError(message, self.source, self.line_of(*keys) if keys else None)

    def table(self, *keys, allowed=None, required=(), renamed=None):
        """The table at `keys`, checked for unknown, renamed and missing keys.

        Parameters
        ----------
        *keys : str or int
            Path of the table (int indexes an array of tables).
        allowed : iterable of str, optional
            Keys the table may hold; any other key is reported with its line.
        required : iterable of str
            Keys the table must hold.
        renamed : mapping str -> str, optional
            Old key -> the key that replaced it; an old key is reported with
            its line and the name to use instead.
        """
        value = self.data
        for i, key in enumerate(keys):
            try:
                value = value[key]
            except (KeyError, IndexError, TypeError):
                raise self.error(f"missing [{_dotted(keys[: i + 1])}]", *keys[:i]) from None
        if not isinstance(value, dict):
            raise self.error(f"{_dotted(keys)} must be a table", *keys)
        if allowed is not None:
            allowed = set(allowed) | set(required)
            for key in value:
                if key in (renamed or {}):
                    raise self.error(f"key '{key}' in [{_dotted(keys)}] is now '{renamed[key]}' (units in the key name): "
                                     f"rename it; every key is listed in {FORMAT_DOC}", *keys, key)
                if key not in allowed:
                    raise self.error(
                        f"unknown key '{key}' in [{_dotted(keys)}]; expected one of: {', '.join(sorted(allowed))} "
                        f"(see {FORMAT_DOC})",
                        *keys,
                        key,
                    )
        for key in required:
            if key not in value:
                raise self.error(f"missing key '{key}' in [{_dotted(keys)}]", *keys)
        return value


def _dotted(keys):
    return ".".join(str(k) for k in keys) if keys else "top level"
