"""Where contoursim writes: atomic file writes, the output folder and the record of what it wrote there.

Every file contoursim writes goes through :func:`atomic_write`: the content
goes to a temporary file in the same folder, renamed onto the target only once
complete, so an interrupted run (Ctrl-C, a full disk) leaves either the old
file or the new one, never a truncated one. A temporary file is named
``.<name>.<pid>-<8 hex digits>.part``; one left by a process that no longer
runs (killed with SIGKILL) is removed by the next write of that folder.

Nothing is written through a symbolic link: a file contoursim replaces is
renamed over the link (the file it pointed at is left as it was), and the
output folder's record is read and appended to only as a plain file.

The record, ``.contoursim-out``, lists the name of each file written, one a
line. A command that names itself (``OutputDir(path, by="sweep")``) also
records the files it writes, on comment lines ``#by sweep NAME``; a file of
that name written later by another is recorded as ``#by - NAME``. The last
such line of a name says which command wrote the file, so that a command
replacing its own earlier set of files removes only those, and takes them
off the record (a file a user saves later under such a name is theirs). To a reader of
the names alone (an earlier contoursim, a user) these lines are comments; a
name recorded by an earlier contoursim is no command's.
"""

import json
import os
import re
import secrets
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import _validate
from .config import read_text
from .exceptions import ConfigError, OutputError

__all__ = ["OutputDir", "atomic_write", "has_form", "json_text", "output_dir", "refused_early", "report_file",
           "strict", "writing"]

_MARKER = ".contoursim-out"
_MARKER_HEADER = "# written by contoursim; the files it wrote here, one per line, are replaced on each run\n"
_BY = "#by "  # a record's line "#by COMMAND NAME": the command that wrote NAME last ("-": none named)
_PART = re.compile(r"\.(?P<name>.+)\.(?P<pid>[0-9]+)-[0-9a-f]{8}\.part")  # atomic_write's temporary files


@dataclass(frozen=True)
class OutputDir:
    """A folder contoursim writes into, and the record of the files it wrote there.

    Making one creates the folder (with its parents) if missing and refuses a
    folder that holds files but was not made by contoursim. A marker file,
    ``.contoursim-out``, lists the names contoursim wrote; :meth:`write`
    writes only new names or names on that list, so no file a user keeps
    there is ever overwritten, and adds a name to the list once its file is
    complete.

    Parameters
    ----------
    path : str or Path
        The folder.
    by : str, optional
        The command writing (e.g. ``"sweep"``), recorded with each file it
        writes: a command that replaces its own earlier files removes those
        of :meth:`written_by`, never a file another command wrote there.

    Raises
    ------
    ConfigError
        `path` is a file, a symbolic link to nothing, or holds files and no
        marker; the marker is a symbolic link or not contoursim's (not UTF-8
        text).
    OutputError
        `path` cannot be created (e.g. no permission).
    """

    path: Path
    by: str = None

    def __post_init__(self):
        if not isinstance(self.path, (str, os.PathLike)):
            raise TypeError(f"the output folder is a folder name (str or Path), got {type(self.path).__name__}")
        if isinstance(self.path, str) and not self.path:  # Path('') would be '.', the working folder
            raise ConfigError("the output folder's name is empty: contoursim writes its plots and files into a "
                              "folder: name one, e.g. 'results'")
        if self.by is not None and (not isinstance(self.by, str) or not self.by or self.by == "-"
                                    or any(c.isspace() for c in self.by)):
            raise ValueError(f"by names the command writing, one word (e.g. 'sweep'), got {self.by!r}")
        out = Path(self.path)
        object.__setattr__(self, "path", out)
        marker = out / _MARKER
        if out.exists() and not out.is_dir():
            raise ConfigError(f"{out} is a file, not a directory; choose another output directory")
        if out.is_symlink() and not out.exists():  # mkdir would not make the folder it names
            raise ConfigError(f"{out} is a symbolic link to {os.readlink(out)}, which does not exist; make that folder "
                              "or choose another output directory")
        if marker.is_symlink():
            raise _linked(marker)
        if out.exists() and any(out.iterdir()) and not marker.is_file():
            raise ConfigError(f"{out} holds files that contoursim did not write; choose another output directory")
        try:
            out.mkdir(parents=True, exist_ok=True)
            with os.fdopen(os.open(marker, os.O_WRONLY | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o666), "w",
                           encoding="utf-8") as stream:
                stream.write(_MARKER_HEADER)
        except FileExistsError:
            pass  # the folder's record, from an earlier run
        except OSError as exc:
            raise OutputError(f"cannot create the output directory {out}: {exc.strerror}") from None
        self.written()  # a marker that is not contoursim's is refused before anything is written
        _remove_stale_parts(out)

    def written(self):
        """Names of the files contoursim wrote into the folder (from its marker).

        Returns
        -------
        set of str

        Raises
        ------
        ConfigError
            The marker is a symbolic link or not UTF-8 text.
        OutputError
            The marker cannot be read.
        """
        return {line for line in self._lines() if line and not line.startswith("#")}

    def written_by(self, command):
        """Names of the files the command `command` wrote into the folder, and no other command after it.

        A name an earlier contoursim recorded, without the command, is no
        command's.

        Parameters
        ----------
        command : str
            As given to :class:`OutputDir` (`by`), e.g. ``"sweep"``.

        Returns
        -------
        set of str

        Raises
        ------
        ConfigError, OutputError
            As :meth:`written`.
        """
        return {name for name, by in self._writers().items() if by == command}

    def _writers(self):
        """Each name the marker's ``#by`` lines give, with the command that wrote its file last (None: none named)."""
        writers = {}
        for line in self._lines():
            if line.startswith(_BY):
                by, _, name = line[len(_BY):].partition(" ")
                writers[name] = None if by == "-" else by
        return writers

    def _lines(self):
        """The lines of the marker, read as a plain file (see :meth:`written`)."""
        marker = self.path / _MARKER
        try:
            with os.fdopen(os.open(marker, os.O_RDONLY | _NOFOLLOW), "rb") as stream:
                data = stream.read()
            ours = data.startswith(_MARKER_HEADER.encode())  # its names are the files' names, bytes not UTF-8 escaped
            lines = data.decode("utf-8", "surrogateescape" if ours else "strict").splitlines()
        except UnicodeDecodeError as exc:
            raise ConfigError(f"{marker} is not contoursim's record of the files it wrote (byte {exc.start} is not "
                              "UTF-8 text): choose another output directory, or delete it if it is yours") from None
        except OSError as exc:
            raise _marker_error(marker, "read", exc) from None
        for number, line in enumerate(lines, 1):  # a name that is no plain file name: not a record contoursim wrote
            if line.startswith(_BY):
                name = line[len(_BY):].partition(" ")[2]
            elif line and not line.startswith("#"):
                name = line
            else:
                continue
            if not _plain(name):
                raise ConfigError(f"{name!r} is not a plain file name: this is not a record contoursim wrote of the "
                                  "files it wrote here; choose another output directory, or mend or delete the file",
                                  str(marker), number)
        return lines

    def file(self, name):
        """The path `name` would be written to, after checking contoursim may write it.

        Use it to refuse a set of names before writing any of them; the
        writing itself goes through :meth:`write`.

        Parameters
        ----------
        name : str
            A file name, without folder.

        Returns
        -------
        Path
            ``path / name``.

        Raises
        ------
        FileExistsError
            A file `name` exists in the folder and contoursim did not write it.
        ValueError
            `name` is not a plain file name.
        """
        if not isinstance(name, str) or not _plain(name):
            raise ValueError(f"name must be a plain file name, got {name!r}")
        file = self.path / name
        if name in self.written():
            return file
        if file.exists() or file.is_symlink():
            raise FileExistsError(f"{file} exists and contoursim did not write it; refusing to overwrite it")
        return file

    @contextmanager
    def write(self, name, binary=False):
        """Write the file `name` atomically (see :func:`atomic_write`) and record it as contoursim's.

        Parameters
        ----------
        name : str
            A file name, without folder: a new name, or one contoursim wrote before.
        binary : bool
            Open in binary mode (e.g. for ``savefig``); text is UTF-8.

        Yields
        ------
        file object
            Open on a temporary file; `name` appears only when the block ends
            without an exception, and is listed in the marker just before
            (a marker that cannot be written leaves no file it does not list).

        Raises
        ------
        FileExistsError
            A file `name` exists in the folder and contoursim did not write it.
        OutputError
            The file, or its line in the marker, cannot be written.
        """
        file = self.file(name)
        with atomic_write(file, binary=binary, before_replace=lambda: self._record(name)) as stream:
            yield stream

    def remove(self, name):
        """Remove the file `name` that contoursim wrote into the folder (a name on its record), if it is there.

        For a run that replaces an earlier run's set of files with fewer: the
        earlier ones it does not write again would be taken for its own. The
        name leaves the record: a file saved later under it is not contoursim's.

        Parameters
        ----------
        name : str
            A file name, without folder.

        Raises
        ------
        FileExistsError
            A file `name` exists in the folder and contoursim did not write it (it is left as it is).
        OutputError
            The file cannot be removed.
        """
        file = self.file(name)
        try:
            file.unlink(missing_ok=True)  # a link contoursim wrote over a file: the link, never what it names
        except OSError as exc:
            raise OutputError(f"cannot remove {file}: {exc.strerror}") from None
        self._unrecord(name)

    def _unrecord(self, name):
        """Take `name` and its ``#by`` lines off the marker (its file removed): a file a user saves later under that
        name is theirs. The marker is replaced as a whole (:func:`atomic_write`), never written through a link."""
        lines = self._lines()
        kept = [line for line in lines if line != name and not (line.startswith(_BY) and
                                                                 line[len(_BY):].partition(" ")[2] == name)]
        if kept == lines:
            return
        marker = self.path / _MARKER
        try:
            with atomic_write(marker, binary=True) as stream:
                stream.write("".join(line + "\n" for line in kept).encode("utf-8", "surrogateescape"))
        except OutputError as exc:
            raise OutputError(f"cannot take {self.path / name} off the record {marker}: {exc}") from None

    def _record(self, name):
        """List `name` in the marker (once) and, when it changes, the command writing it (``#by``), appending to the
        marker as a plain file, never through a link."""
        lines = [] if name in self.written() else [name]
        if self._writers().get(name) != self.by:  # who wrote it changes (or a named command's first write)
            lines.append(f"{_BY}{self.by or '-'} {name}")
        if not lines:
            return
        marker = self.path / _MARKER
        try:
            with os.fdopen(os.open(marker, os.O_WRONLY | os.O_APPEND | _NOFOLLOW), "w", encoding="utf-8",
                           errors="surrogateescape") as stream:  # a name of bytes not UTF-8 (os.fsdecode), as they are
                stream.write("".join(line + "\n" for line in lines))
        except OSError as exc:
            raise _marker_error(marker, f"record {self.path / name} in", exc) from None

    def __str__(self):
        return str(self.path)


def _plain(name):
    """Whether the text `name` is a plain file name (no folder), one contoursim may write in an output folder."""
    return Path(name).name == name and name not in ("", ".", "..", _MARKER) and "\n" not in name


def output_dir(out):
    """The output folder `out`, created or reused (see :class:`OutputDir`).

    Parameters
    ----------
    out : str, Path or OutputDir
        The folder; an :class:`OutputDir` is returned as is.

    Returns
    -------
    OutputDir

    Raises
    ------
    ConfigError
        `out` is a file, cannot be created, or holds files that contoursim did not write.
    """
    return out if isinstance(out, OutputDir) else OutputDir(out)


def refused_early(out, names):
    """Refuse now what writing `names` into the folder `out` would refuse at the end of a long run (a diagnosis).

    An existing `out` is checked as :func:`output_dir` and :meth:`OutputDir.file` check it; one that does not exist
    yet is left to be made when written to (a run that ends in an error leaves no folder).

    Parameters
    ----------
    out : str or Path
        The output folder.
    names : iterable of str
        The file names the run will write there.

    Raises
    ------
    ConfigError
        As :func:`output_dir`.
    FileExistsError
        As :meth:`OutputDir.file`.
    ValueError
        A name that is no plain file name (as :meth:`OutputDir.file`), whether `out` exists or not.
    """
    names = list(names)
    for name in names:
        if not isinstance(name, str) or not _plain(name):
            raise ValueError(f"cannot write {name!r} into {out}: it is no plain file name (a folder or a line break "
                             "in it); rename the file it is named after")
    if os.path.lexists(out):
        folder = output_dir(out)
        for name in names:
            folder.file(name)


_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)  # POSIX; opening a symbolic link with it fails (ELOOP)


def _linked(marker):
    """The error of a marker that is a symbolic link (never followed: it could point at a user's file)."""
    return ConfigError(f"{marker} is a symbolic link; contoursim keeps its record of the files it wrote only "
                       "as a plain file: remove the link or choose another output directory")


def _marker_error(marker, doing, exc):
    """The error of a marker that cannot be read or appended to, saying why."""
    return _linked(marker) if marker.is_symlink() else OutputError(f"cannot {doing} {marker}: {exc.strerror}")


def _alive(pid):
    """Whether process `pid` may still run (on this machine); True where it cannot be told."""
    if pid == os.getpid() or os.name != "posix":
        return True
    try:
        os.kill(pid, 0)  # signal 0: nothing is sent, the process's existence is checked
    except ProcessLookupError:
        return False
    except OSError:  # e.g. another user's process
        return True
    return True


def _remove_stale_parts(folder, name=None):
    """Remove the temporary files of :func:`atomic_write` in `folder` (of `name` only, if given) whose writer is gone.

    Only plain files named as :func:`atomic_write` names them, by a process
    that no longer runs, are removed; anything else is left as it is.
    """
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return
    for entry in entries:
        match = _PART.fullmatch(entry.name)
        if (match and (name is None or match["name"] == name) and entry.is_file(follow_symlinks=False)
                and not _alive(int(match["pid"]))):
            try:
                os.unlink(entry.path)
            except OSError:
                pass  # e.g. removed by another run meanwhile


def report_file(file, form, what, out=None, written=(), also=()):
    """Check that a JSON report may be written to `file`: a new name, or a report contoursim wrote there before.

    An existing file is taken for such a report only if it has the report's
    form (:func:`has_form`), not for a key it shares with one: a user's
    ``{"runs": {"my": "notes"}}`` is not a comparison JSON, nor is one of
    contoursim's reports to which the user added notes of their own.

    Parameters
    ----------
    file : str or Path or None
        The report's file (``None``: no report).
    form : dict of str -> tuple of str or None
        The form of every such report (see :func:`has_form`), e.g.
        :data:`contoursim.comparison.JSON_FORM`.
    what : str
        What the report is, for the messages (e.g. ``"comparison JSON"``).
    out : str or Path, optional
        The output folder of the same run, not made yet: the report may not be it.
    written : collection of str
        Names of the files the run writes into `out`: the report may not be one of them, nor the folder's record.
    also : collection of str
        The keys such a report may have besides those of `form` (:func:`has_form`).

    Returns
    -------
    Path or None

    Raises
    ------
    ConfigError
        `file` is a directory, the output folder `out`, or a file the run writes there; its folder does not
        exist (and is not `out`, which the run makes).
    FileExistsError
        `file` exists and is not such a report: it is the user's, never overwritten.
    """
    if file is None:
        return None
    file = Path(file)
    if out is not None and file.resolve() == Path(out).resolve():  # the folder made first, the report refused after it
        raise ConfigError(f"{file} is the output directory (--out); name a file to write the {what} to")
    if out is not None and file.name in {*written, _MARKER} and file.resolve().parent == Path(out).resolve():
        raise ConfigError(f"{file} is a file this run writes into its output directory (--out); name another file to "
                          f"write the {what} to")
    if file.is_dir():
        raise ConfigError(f"{file} is a directory; name a file to write the {what} to")
    if not file.parent.is_dir() and (out is None or file.parent.resolve() != Path(out).resolve()):
        raise ConfigError(f"{file}: there is no folder {file.parent} to write the {what} into; make it, or name a "
                          "file in a folder that exists (or in --out)")
    if file.exists() or file.is_symlink():
        try:
            data = json.loads(read_text(file))
        except (OSError, ValueError, RecursionError):  # unreadable, not a regular file, not UTF-8, not JSON, nested deep
            data = None
        if not has_form(data, form, also):
            added = sorted(set(data) - {*form, *also}) if has_form(data, form) else ()  # a report the user wrote in
            raise FileExistsError(f"{file} exists and is not a {what}" + (
                f" as contoursim writes it (it holds {', '.join(map(repr, added))} besides)" if added else "")
                + "; refusing to overwrite it")
    return file


def has_form(data, form, also=None):
    """Whether `data`, read from JSON, has the form of a report contoursim writes.

    That is an object with each key of `form` at its top level; where
    `form` names keys for one, its value is an object or a list each of
    whose entries (values, items) is an object with those keys. With
    `also`, no top-level key but those of `form` and `also`: a key a user
    added (their notes) makes the file theirs, while an earlier version's
    report, with fewer keys, is still taken for one.

    Parameters
    ----------
    data : object
        As :func:`json.loads` gives it.
    form : dict of str -> tuple of str or None
        Each top-level key of the report, with the keys each entry of its
        value has (or None: any value), e.g. ``{"runs": ("contour_max_um",
        ...), "axes": ("phase_margin_deg", "damping_ratio")}``.
    also : collection of str, optional
        The keys the report may have besides (``None``: any).

    Returns
    -------
    bool

    Examples
    --------
    >>> form = {"runs": ("contour_max_um",), "axes": None}
    >>> has_form({"runs": {"none": {"contour_max_um": 3.2}}, "axes": {}}, form)
    True
    >>> has_form({"runs": {"my": "notes"}, "axes": {}}, form)
    False
    >>> has_form({"runs": {}, "axes": {}, "notes": "mine"}, form, also=())
    False
    """
    if not isinstance(data, dict) or not set(form) <= set(data):
        return False
    if also is not None and not set(data) <= {*form, *also}:
        return False
    for key, keys in form.items():
        if keys is None:
            continue
        entries = list(data[key].values()) if isinstance(data[key], dict) else data[key]
        if not isinstance(entries, list) or not all(isinstance(e, dict) and set(keys) <= set(e) for e in entries):
            return False
    return True


def json_text(data):
    """`data` (nested dicts, lists, numbers, text) as strict JSON text, indented: no NaN or Infinity, which strict
    readers refuse (a loop margin that does not exist, infinite), but ``null``; numpy's numbers as Python's.

    Parameters
    ----------
    data : object
        A report: dicts, lists and tuples of text, booleans, numbers and ``None``.

    Returns
    -------
    str

    Examples
    --------
    >>> print(json_text({"phase_margin_deg": float("inf"), "frames": 3}))
    {
      "phase_margin_deg": null,
      "frames": 3
    }
    """
    return json.dumps(strict(data), indent=2, ensure_ascii=False, allow_nan=False)


def strict(value):
    """`value` with every number a plain float or int and each non-finite one ``None``: a report as strict JSON holds
    it (:func:`json_text`).

    Parameters
    ----------
    value : object
        Nested dicts, lists and tuples of text, booleans, numbers (numpy's too) and ``None``.

    Returns
    -------
    object
        Dicts, lists, ``bool``, ``int``, ``float`` (finite) and ``None`` in its place.
    """
    if isinstance(value, dict):
        return {k: strict(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [strict(v) for v in value]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return float(value) if np.isfinite(value) else None
    return value


@contextmanager
def atomic_write(file, binary=False, before_replace=None):
    """Write `file` through a temporary file in the same folder, renamed onto `file` when complete.

    If the block raises (or is interrupted), the temporary file is removed and
    `file` is left as it was. A symbolic link `file` is replaced, not written
    through. Temporary files of `file` left by killed processes are removed
    first (see the module docstring).

    Parameters
    ----------
    file : str or Path
        The file to create or replace.
    binary : bool
        Open in binary mode; text is UTF-8 with the newlines written as given
        (a file name of bytes that are not UTF-8, as :func:`os.fsdecode` gives
        it, has them escaped: ``\\xff``).
    before_replace : callable, optional
        Called without arguments once the content is complete, just before
        it replaces `file`; if it raises, `file` is left as it was.

    Yields
    ------
    file object

    Raises
    ------
    OutputError
        The folder is not writable, the disk is full, ... (naming `file`).
    """
    file, binary = Path(file), _validate.flag("binary", binary)
    _remove_stale_parts(file.parent, file.name)
    temporary = file.with_name(f".{file.name}.{os.getpid()}-{secrets.token_hex(4)}.part")
    try:
        stream = (open(temporary, "xb") if binary  # a file name of bytes not UTF-8 in the text: escaped (\\xff)
                  else open(temporary, "x", encoding="utf-8", errors="backslashreplace", newline=""))
    except OSError as exc:
        raise OutputError(f"cannot write {file}: {exc.strerror}") from None
    try:
        with stream:
            yield stream
        if before_replace is not None:
            before_replace()
        os.replace(temporary, file)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
        if isinstance(exc, OutputError):  # from before_replace, saying what failed
            raise
        raise OutputError(f"cannot write {file}: {exc.strerror}") from None
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def writing(file, overwrite=False, binary=False):
    """A context giving a stream to write to: `file` itself if it is a file object, else :func:`atomic_write`.

    The common front of contoursim's writers (traces, error tables), which
    take a file name or an open file object.

    Parameters
    ----------
    file : str, Path or file object
        Destination.
    overwrite : bool
        Replace an existing file (for a file name).
    binary : bool
        Open a file name in binary mode.

    Raises
    ------
    TypeError
        `file` is neither a file name nor a file object.
    IsADirectoryError
        `file` names a folder.
    FileExistsError
        `file` names an existing file and `overwrite` is false.
    """
    overwrite, binary = _validate.flag("overwrite", overwrite), _validate.flag("binary", binary)
    if hasattr(file, "write"):
        return nullcontext(file)
    if not isinstance(file, (str, os.PathLike)):  # pathlib's "expected str, bytes or os.PathLike object, not int"
        raise TypeError(f"expected a file name (str or Path) or a file object to write to, got {type(file).__name__}")
    file = Path(file)
    if file.is_dir():  # "exists; refusing to overwrite it", which overwrite=True would not have helped
        raise IsADirectoryError(f"{file} is a folder: give a file name in it (e.g. {file / 'run.csv'})")
    if file.exists() and not overwrite:
        raise FileExistsError(f"{file} exists; refusing to overwrite it")
    return atomic_write(file, binary=binary)
