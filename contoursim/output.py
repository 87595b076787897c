"""Where contoursim writes: atomic file writes, the output folder and the record of what it wrote there.

Every file contoursim writes goes through :func:`atomic_write`: the content
goes to a temporary file in the same folder, renamed onto the target only once
complete, so an interrupted run (Ctrl-C, a full disk) leaves either the old
file or the new one, never a truncated one.
"""

import os
import secrets
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path

from .exceptions import ConfigError, OutputError

__all__ = ["OutputDir", "atomic_write", "output_dir", "writing"]

_MARKER = ".contoursim-out"
_MARKER_HEADER = "# written by contoursim; the files it wrote here, one per line, are replaced on each run\n"


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

    Raises
    ------
    ConfigError
        `path` is a file or holds files and no marker.
    OutputError
        `path` cannot be created (e.g. no permission).
    """

    path: Path

    def __post_init__(self):
        out = Path(self.path)
        object.__setattr__(self, "path", out)
        marker = out / _MARKER
        if out.exists() and not out.is_dir():
            raise ConfigError(f"{out} is a file, not a directory; choose another output directory")
        if out.exists() and any(out.iterdir()) and not marker.is_file():
            raise ConfigError(f"{out} holds files that contoursim did not write; choose another output directory")
        try:
            out.mkdir(parents=True, exist_ok=True)
            if not marker.exists():
                marker.write_text(_MARKER_HEADER, encoding="utf-8")
        except OSError as exc:
            raise OutputError(f"cannot create the output directory {out}: {exc.strerror}") from None

    def written(self):
        """Names of the files contoursim wrote into the folder (from its marker).

        Returns
        -------
        set of str
        """
        lines = (self.path / _MARKER).read_text(encoding="utf-8").splitlines()
        return {line for line in lines if line and not line.startswith("#")}

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
        if not isinstance(name, str) or Path(name).name != name or name in ("", ".", "..", _MARKER) or "\n" in name:
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
            Open on a temporary file; `name` appears, and is listed in the
            marker, only when the block ends without an exception.

        Raises
        ------
        FileExistsError
            A file `name` exists in the folder and contoursim did not write it.
        OutputError
            The file cannot be written.
        """
        file = self.file(name)
        with atomic_write(file, binary=binary) as stream:
            yield stream
        if name not in self.written():
            try:
                with open(self.path / _MARKER, "a", encoding="utf-8") as marker:
                    marker.write(name + "\n")
            except OSError as exc:
                raise OutputError(f"cannot record {file} in {self.path / _MARKER}: {exc.strerror}") from None

    def __str__(self):
        return str(self.path)


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


@contextmanager
def atomic_write(file, binary=False):
    """Write `file` through a temporary file in the same folder, renamed onto `file` when complete.

    If the block raises (or is interrupted), the temporary file is removed and
    `file` is left as it was.

    Parameters
    ----------
    file : str or Path
        The file to create or replace.
    binary : bool
        Open in binary mode; text is UTF-8 with the newlines written as given.

    Yields
    ------
    file object

    Raises
    ------
    OutputError
        The folder is not writable, the disk is full, ... (naming `file`).
    """
    file = Path(file)
    temporary = file.with_name(f".{file.name}.{secrets.token_hex(4)}.part")
    try:
        stream = open(temporary, "xb") if binary else open(temporary, "x", encoding="utf-8", newline="")
    except OSError as exc:
        raise OutputError(f"cannot write {file}: {exc.strerror}") from None
    try:
        with stream:
            yield stream
        os.replace(temporary, file)
    except OSError as exc:
        temporary.unlink(missing_ok=True)
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
    FileExistsError
        `file` names an existing file and `overwrite` is false.
    """
    if hasattr(file, "write"):
        return nullcontext(file)
    file = Path(file)
    if file.exists() and not overwrite:
        raise FileExistsError(f"{file} exists; refusing to overwrite it")
    return atomic_write(file, binary=binary)
