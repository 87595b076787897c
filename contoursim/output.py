"""The folder contoursim writes its files into, and the record of what it wrote there."""

from dataclasses import dataclass
from pathlib import Path

from .exceptions import ConfigError

__all__ = ["OutputDir", "output_dir"]

_MARKER = ".contoursim-out"
_MARKER_HEADER = "# written by contoursim; the files it wrote here, one per line, are replaced on each run\n"


@dataclass(frozen=True)
class OutputDir:
    """A folder contoursim writes into, and the record of the files it wrote there.

    Making one creates the folder (with its parents) if missing and refuses a
    folder that holds files but was not made by contoursim. A marker file,
    ``.contoursim-out``, lists the names contoursim wrote; :meth:`file` hands
    out paths only for new names or names on that list, so no file a user
    keeps there is ever overwritten.

    Parameters
    ----------
    path : str or Path
        The folder.

    Raises
    ------
    ConfigError
        `path` is a file, cannot be created, or holds files and no marker.
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
            raise ConfigError(f"cannot create the output directory {out}: {exc.strerror}") from None

    def written(self):
        """Names of the files contoursim wrote into the folder (from its marker).

        Returns
        -------
        set of str
        """
        lines = (self.path / _MARKER).read_text(encoding="utf-8").splitlines()
        return {line for line in lines if line and not line.startswith("#")}

    def file(self, name):
        """The path to write `name` to; records `name` as written by contoursim.

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
        with open(self.path / _MARKER, "a", encoding="utf-8") as marker:
            marker.write(name + "\n")
        return file

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
