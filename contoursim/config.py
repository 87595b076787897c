"""TOML configuration files with errors that point at the line.

:mod:`tomllib` parses but forgets where a value came from. :class:`TomlFile`
keeps the text so that a bad or unknown key can be reported as
``machine.toml, line 12: unknown key 'kpp' in [axes.x]; expected one of ...``.
"""

import bisect
import json
import math
import numbers
import os
import re
import stat
import tomllib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

import numpy as np

from ._validate import FLOAT_MAX, closest, shown
from .exceptions import ConfigError

__all__ = ["FORMAT_DOC", "TEXT_KEYS", "TomlFile", "local_file", "read_bytes", "read_text", "text_lines", "text_only",
           "toml_text", "unique_columns"]

#: Where messages send a user for the keys of every file.
FORMAT_DOC = "docs/machines-and-files.md, section 'File format'"
#: The keys of a file's free text and what each is (:meth:`TomlFile.table`'s `text`).
TEXT_KEYS = MappingProxyType({"name": "text", "description": "text"})

# what each kind of file looks like, for a message when one is given where another is expected
_KINDS = {
    "job": 'names a machine and a path (machine = "demo_mill", path = "iso230_4_circle_ccw": presets, library '
           "names or files), optionally with [feed], work_offset and geometric_compensation",
    "path": 'describes a path: a [path] table (type = "circle", ...) and a [feed] table',
    "machine": "describes a machine: servo_period_ms and an [axes.<name>] table per servo axis, optionally "
               "[[body]] tables for its geometry (the presets in contoursim/presets/ are examples)",
}


# the leading bytes of compressed files a logger or an archive leaves under a .csv or .toml name
_PACKED = {b"\x1f\x8b": "gzip-compressed", b"PK\x03\x04": "a ZIP archive",
           b"\xfd7zXZ\x00": "xz-compressed", b"\x28\xb5\x2f\xfd": "zstd-compressed"}


def local_file(name, folder=".", suffixes=()):
    """The file `name` in `folder`, or `name` with one of `suffixes` added there; None when there is none.

    A name of a preset or library entry (``"demo_mill"``, ``"rounded_square"``) is looked for here first, so a
    user's own copy of it (``rounded_square.toml``, edited) is the one read, not the one shipped.

    Parameters
    ----------
    name : str or os.PathLike
        A file name, with or without its suffix.
    folder : str or os.PathLike
        Where to look (a relative `name` is relative to it).
    suffixes : sequence of str
        Suffixes tried in turn after `name` itself (``(".toml", ".nc")``).

    Returns
    -------
    pathlib.Path or None
    """
    for candidate in (str(name), *(f"{name}{suffix}" for suffix in suffixes)):
        file = Path(folder) / candidate
        if file.exists():
            return file
    return None


def read_bytes(file, error=ConfigError):
    """The bytes of the text file `file`, with errors naming the file.

    A named pipe, a device (``/dev/zero``, a link to one) or a socket is
    refused before anything is read: reading one would block until another
    program writes, or never end. So is a compressed file (gzip, ZIP, xz,
    zstd: a logger's archive under a ``.csv`` name), by its first bytes.

    Parameters
    ----------
    file : str or Path
        The file.
    error : type
        The :class:`ConfigError` subclass to raise.

    Raises
    ------
    ConfigError
        The file cannot be read, is not a regular file or is compressed.
    TypeError
        `file` is not a file name.
    """
    if not isinstance(file, (str, os.PathLike)):
        raise TypeError(f"expected a file name (str or Path), got {type(file).__name__}")
    try:
        fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # a FIFO opens at once, without a writer
    except OSError as exc:
        raise error(f"cannot read the file: {exc.strerror}", str(file)) from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = ("a directory" if stat.S_ISDIR(mode) else "a named pipe (FIFO)" if stat.S_ISFIFO(mode)
                else "a socket" if stat.S_ISSOCK(mode) else "a device")
        raise error(f"cannot read the file: it is {kind}, not a regular file", str(file))
    with os.fdopen(fd, "rb") as stream:
        try:
            raw = stream.read()
        except OSError as exc:
            raise error(f"cannot read the file: {exc.strerror}", str(file)) from None
    packed = next((name for magic, name in _PACKED.items() if raw.startswith(magic)), None)
    if packed:
        raise error(f"the file is {packed}, not text: unpack it first", str(file), 1)
    return raw


def named_as(file, suffix, what, error=ConfigError):
    """Refuse `file` where its name ends as another kind of file contoursim reads than `suffix` (a G-code program, a
    ``.csv`` table or a ``.toml`` file) says: given as a machine file or a trace, a G-code program was refused by the
    other format's first complaint ("not valid TOML", "missing column 't' in the header '%'")."""
    from .gcode import SUFFIXES

    found = Path(str(file)).suffix.lower()
    kinds = {".toml": "a TOML file", ".csv": "a CSV table", **dict.fromkeys(SUFFIXES, "a G-code program")}
    if found != suffix and found in kinds:
        raise error(f"this is {kinds[found]} (by its name), not {what}", str(file))


def read_text(file, error=ConfigError):
    """The UTF-8 text of `file` (a leading byte-order mark dropped), with errors naming the file.

    Parameters
    ----------
    file : str or Path
        The file.
    error : type
        The :class:`ConfigError` subclass to raise.

    Raises
    ------
    ConfigError
        The file cannot be read, is not a regular file or is compressed
        (:func:`read_bytes`), or is not UTF-8 text (UTF-16, a NUL byte:
        naming the line).
    """
    raw = read_bytes(file, error)
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):  # UTF-16's byte-order marks (and little-endian UTF-32's)
        raise error("the file is UTF-16 text (by its byte-order mark): save it as UTF-8", str(file), 1)
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        raise error(f"byte 0x{raw[exc.start]:02X} is not UTF-8 text: save the file as UTF-8", str(file), line) from None
    return text_only(text, file, error)


def text_only(text, file, error=ConfigError):
    """`text` read from `file`, unless it holds a NUL byte: no text file does (UTF-16 without its mark, or binary).

    Parameters
    ----------
    text : str
        The file's decoded text.
    file : str or Path
        The file, for the message.
    error : type
        The :class:`ConfigError` subclass to raise.

    Returns
    -------
    str
        `text`.

    Raises
    ------
    ConfigError
        Naming the file and the line of the first NUL byte.
    """
    if "\x00" in text:
        line = text.count("\n", 0, text.index("\x00")) + 1
        raise error("byte 0x00 (NUL) is not text (UTF-16 without a byte-order mark, or a binary file?): save the file "
                    "as UTF-8 text", str(file), line)
    return text


def unique_columns(names, file, line, error=ConfigError):
    """Refuse a CSV header naming a column more than once: one copy would be read, the others dropped without a word.

    Parameters
    ----------
    names : list of str
        The header's column names.
    file : str or Path
        The file, for the message.
    line : int
        The header's 1-based line.
    error : type
        The :class:`ConfigError` subclass to raise.

    Raises
    ------
    ConfigError
        Naming the file, the header's line and the repeated names.
    """
    repeated = sorted(name for name, count in Counter(names).items() if count > 1)
    if repeated:
        raise error(f"column name(s) {', '.join(map(repr, repeated))} appear more than once in the header", str(file),
                    line)


def toml_text(data):
    """TOML text of the table `data`, which :mod:`tomllib` reads back as `data`: what a file the reader read holds.

    Parameters
    ----------
    data : mapping
        Text keys; values text, booleans, numbers (finite or not), lists and tables of them. A table is written
        as a ``[table]`` section and a list of tables as ``[[table]]`` sections (a file's ``[[body]]`` with its
        ``[body.errors]``), a table within a list as an inline one.

    Returns
    -------
    str
    """
    lines = []
    _toml_section(lines, "", data, "")
    return "\n".join(lines).lstrip("\n") + "\n"


def _toml_string(text):
    # JSON's escapes are a TOML basic string's; DEL, which JSON leaves as it is, TOML wants escaped
    return json.dumps(text, ensure_ascii=False).replace("\x7f", "\\u007f")


def _toml_key(key):
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else _toml_string(key)


def _toml_tables(value):
    return isinstance(value, list) and bool(value) and all(isinstance(item, dict) for item in value)


def _toml_value(value):
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (bool, np.bool_)):
        return "true" if value else "false"
    if isinstance(value, numbers.Integral):
        return str(int(value))
    if isinstance(value, numbers.Real):
        return repr(float(value))  # 'inf', 'nan' and '1e-06' are TOML floats
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_key(k)} = {_toml_value(v)}" for k, v in value.items()) + "}"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_toml_value(v) for v in value) + "]"
    raise TypeError(f"a TOML value is text, a boolean, a number, a list or a table, got {type(value).__name__}")


def _toml_section(lines, header, table, prefix):
    """`table`'s keys after `header`, then its tables and lists of tables as sections named from `prefix`.

    A ``[table]`` of tables alone goes without its header (its tables' sections make it)."""
    nested = {k: v for k, v in table.items() if isinstance(v, dict) or _toml_tables(v)}
    if header and (header.startswith("[[") or len(nested) < len(table) or not table):
        lines += ["", header]
    lines += [f"{_toml_key(k)} = {_toml_value(v)}" for k, v in table.items() if k not in nested]
    for k, v in nested.items():
        name = prefix + _toml_key(k)
        if isinstance(v, dict):
            _toml_section(lines, f"[{name}]", v, name + ".")
        else:
            for item in v:
                _toml_section(lines, f"[[{name}]]", item, name + ".")


_LINE_END = re.compile(r"\r\n|\r|\n")


def text_lines(text):
    r"""The lines of `text` as an editor numbers them: split at ``\n``, ``\r\n`` and ``\r`` only.

    :meth:`str.splitlines` also splits at a form feed, at U+0085 (byte 0x85,
    a Latin-1 file's "…") and at other separators, which numbered the lines
    after them one too far (and cut a comment holding one in two).

    Parameters
    ----------
    text : str

    Returns
    -------
    list of str
        Without their line ends; no empty line after a final line end.

    Examples
    --------
    >>> text_lines("G1 X1 (caf\x85)\r\nG1 Y1\x0c\n")
    ['G1 X1 (caf\x85)', 'G1 Y1\x0c']
    """
    lines = _LINE_END.split(text)
    return lines[:-1] if lines[-1] == "" else lines


_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY = re.compile(r"""^\s*("[^"]*"|'[^']*'|[A-Za-z0-9_\-]+(?:\s*\.\s*[A-Za-z0-9_\-]+)*)\s*=""")


# a TOML line's tokens that open or close what may go on over the next lines (multi-line strings, arrays), its
# one-line strings (whose brackets are text) and its comment; and what closes each kind of multi-line string
_CLOSE = {'"""': re.compile(r'(?:[^"\\]|\\.|"(?!""))*"""'), "'''": re.compile(r"(?:[^']|'(?!''))*'''")}
_TOKEN = re.compile("|".join([*map(re.escape, _CLOSE), r'"(?:[^"\\]|\\.)*"?', r"'[^']*'?", "#", r"\[", r"\]"]))


def _continued(lines):
    """Per line of a TOML text, whether it starts inside a multi-line string or array: a value's continuation, whose
    ``[axes.x]`` or ``kp_per_s = 35`` (a description's notes) is text, no table header or key."""
    inside, depth, flags = None, 0, []
    for line in lines:
        flags.append(inside is not None or depth > 0)
        pos = 0
        while True:
            if inside is not None:
                close = _CLOSE[inside].match(line, pos)
                if close is None:  # the string goes on over the next line
                    break
                pos, inside = close.end(), None
                continue
            token = _TOKEN.search(line, pos)
            if token is None or token.group() == "#":
                break
            if token.group() in _CLOSE:
                inside = token.group()
            elif token.group() in "[]":
                depth = max(depth + (1 if token.group() == "[" else -1), 0)
            pos = token.end()
    return flags


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
            data = tomllib.loads(self.text, parse_float=_float)
        except tomllib.TOMLDecodeError as exc:
            line = re.search(r"line (\d+)", str(exc))
            raise ConfigError(f"not valid TOML: {exc}", self.source, int(line.group(1)) if line else None) from None
        except RecursionError:  # tomllib recurses into each array and inline table: a few hundred exhaust the stack
            raise ConfigError("not valid TOML: arrays or inline tables nested too deeply", self.source,
                              _too_deep_line(self.text)) from None
        except ValueError:  # tomllib's int() of more than 4300 digits
            digits = re.search(r"\d[\d_]{4300,}", self.text)
            line = self.text.count("\n", 0, digits.start()) + 1 if digits else None
            raise ConfigError("a whole number of more than 4300 digits is too large a number", self.source, line) from None
        object.__setattr__(self, "data", data)
        found = _too_large(data)
        if found:
            keys, value = found
            leaf = max(i for i, k in enumerate(keys) if isinstance(k, str))  # an array of tables' item is counted
            where = f" in {_table(keys[:leaf])}" if any(isinstance(k, int) for k in keys[:leaf]) else ""
            written = shown(getattr(value, "text", value))
            raise self.error(f"{_dotted(keys[leaf:] if where else keys)}{where} = {written} is too large a number: "
                             f"beyond ±{FLOAT_MAX:.4g}", *keys)

    @classmethod
    def read(cls, path):
        """Read and parse the TOML file at `path`."""
        named_as(path, ".toml", "a TOML file (a machine, path, job or sweep file)")
        return cls(str(path), read_text(path))

    def kind(self):
        """What the file is by its top-level keys: ``"job"``, ``"path"``, ``"machine"`` or ``None``.

        A job file has ``machine`` or a ``path`` string; a path file a
        ``[path]`` or ``[feed]`` table; a machine file ``[axes]``, ``[[body]]``
        or ``servo_period_ms``.
        """
        data = self.data
        if "machine" in data or isinstance(data.get("path"), str):
            return "job"
        if "path" in data or "feed" in data:
            return "path"
        if any(key in data for key in ("axes", "body", "servo_period_ms")):
            return "machine"
        return None

    def expect(self, kind):
        """Check that the file is of `kind` (see :meth:`kind`), saying what such a file looks like if not.

        Parameters
        ----------
        kind : {"job", "path", "machine"}

        Raises
        ------
        ConfigError
            The file is empty or of another kind.
        """
        found = self.kind()
        if not self.data:
            raise self.error(f"the file is empty; a {kind} file {_KINDS[kind]}")
        if found not in (None, kind):
            raise self.error(f"this is a {found} file, not a {kind} file; a {kind} file {_KINDS[kind]}")

    def line_of(self, *keys):
        """1-based line that defines the key path `keys`, or ``None``.

        `keys` walks tables by name and arrays of tables by index, e.g.
        ``line_of("body", 2, "joint")`` is the ``joint =`` line of the third
        ``[[body]]``. When the last key is not written on a line of its own
        (inline tables), the line of the closest enclosing key is returned; a
        table that only its sub-tables' headers define (``[axes]`` by
        ``[axes.x]``), the line of the first of them.
        """
        best = inside = None
        table = ()
        counts = {}
        lines = text_lines(self.text)
        for number, (line, continued) in enumerate(zip(lines, _continued(lines)), start=1):
            if continued:  # inside a multi-line string or array: text or values, no header or key
                continue
            header = _HEADER.match(line)
            if header:
                path = _split_key(header.group(2))
                if header.group(1) == "[[":
                    counts[path] = counts.get(path, -1) + 1
                table = self._indexed(path, counts)
                if table == keys[: len(table)] and (best is None or len(table) > best[0]):
                    best = (len(table), number)
                elif inside is None and keys and table[: len(keys)] == keys:
                    inside = number
                continue
            key = _KEY.match(line)
            if key:
                full = table + _split_key(key.group(1))
                if full == keys[: len(full)] and (best is None or len(full) > best[0]):
                    best = (len(full), number)
        return inside if best is None else best[1]

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

    def table(self, *keys, allowed=None, required=(), renamed=None, text=None):
        """The table at `keys`, checked for unknown, renamed and missing keys and for text that is not text.

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
        text : mapping str -> str, optional
            Keys whose values must be strings -> what the value is (``"a
            name"``); a number, boolean, list or table there is reported with
            its line (TOML would read ``name = 3`` as a number).
        """
        value = self.data
        for i, key in enumerate(keys):
            try:
                value = value[key]
            except (KeyError, IndexError, TypeError):
                raise self.error(f"missing {_table(keys[: i + 1])}", *keys[:i]) from None
        if not isinstance(value, dict):
            raise self.error(f"{_table(keys)} must be a table", *keys)
        if allowed is not None:
            allowed = set(allowed) | set(required)
            for key in value:
                if key in (renamed or {}):
                    raise self.error(f"key '{key}' in {_table(keys)} is now '{renamed[key]}' (units in the key name): "
                                     f"rename it; every key is listed in {FORMAT_DOC}", *keys, key)
                if key not in allowed:
                    raise self.error(
                        f"unknown key '{key}' in {_table(keys)}{closest(key, allowed)}; expected one of: "
                        f"{', '.join(sorted(allowed))} "
                        f"(see {FORMAT_DOC})",
                        *keys,
                        key,
                    )
        for key in required:
            if key not in value:
                raise self.error(f"missing key '{key}' in {_table(keys)}", *keys)
        for key, what in (text or {}).items():
            where = f" in {_table(keys)}" if keys else ""
            if key in value and not isinstance(value[key], str):
                raise self.error(f"{key}{where} must be {what} in quotes, got {value[key]!r}", *keys, key)
            if key == "name" and key in value and re.search(r"[\r\n]", value[key]):  # it heads a '# key: value' line
                raise self.error(f"{key}{where} must be one line, got {value[key]!r}", *keys, key)
        return value


class _Overflowed(float):
    """A float the file writes beyond a float's range (``1e400``): infinite, with the text as written."""

    def __new__(cls, text):
        value = super().__new__(cls, text)
        value.text = text
        return value


def _float(text):
    """A TOML float: ``inf`` is infinite as written, a finite number too large for a float is :class:`_Overflowed`."""
    value = float(text)
    return _Overflowed(text) if math.isinf(value) and "inf" not in text else value


def _too_deep_line(text):
    """The line where the nesting of `text` exhausts :mod:`tomllib`'s stack: the last of the fewest lines that do."""
    lines = text.split("\n")

    def exhausts(count):
        try:
            tomllib.loads("\n".join(lines[:count]))
        except RecursionError:
            return True
        except ValueError:  # the prefix cuts an array or a string short
            pass
        return False

    return bisect.bisect_left(range(1, len(lines) + 1), True, key=exhausts) + 1


def _too_large(value, keys=()):
    """``(key path, value)`` of the first number in `value` (a TOML document) beyond a float's range, or None."""
    if isinstance(value, (dict, list)):
        for key, item in value.items() if isinstance(value, dict) else enumerate(value):
            found = _too_large(item, (*keys, key))
            if found:
                return found
        return None
    overflowed = isinstance(value, _Overflowed) or (isinstance(value, int) and abs(value) > FLOAT_MAX)
    return (keys, value) if overflowed else None


def _dotted(keys):
    """A value's key path as written: ``servo.kp``, an array's item by its index (``points[2][0]``)."""
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in keys).lstrip(".")


def _table(keys):
    """The table at key path `keys` as a file's reader counts: ``[servo]``, ``the 2nd [[body]]``, ``[body.errors] of
    the 2nd [[body]]``; ``the file's top level`` for none."""
    if not keys:
        return "the file's top level"
    last = max((i for i, k in enumerate(keys) if isinstance(k, int)), default=None)
    if last is None:
        return f"[{'.'.join(keys)}]"
    array = f"[[{_dotted(keys[:last])}]]"
    n = keys[last] + 1
    item = f"the {n}{'th' if n % 100 in (11, 12, 13) else {1: 'st', 2: 'nd', 3: 'rd'}.get(n % 10, 'th')} {array}"
    rest = keys[last + 1:]
    return f"[{_dotted(keys[:last] + rest)}] of {item}" if rest else item
