"""Exceptions raised by contoursim.

Every error a user can cause is one of these, subclassing the built-in
exception a Python programmer would expect (``TypeError`` for a value of the
wrong type, ``ValueError`` for bad values, ``OSError`` for a file that cannot
be written), with a message that names what is wrong and where.
"""

__all__ = ["ChainError", "ConfigError", "ContoursimWarning", "OutputError", "TraceFormatError", "UnstableLoopError",
           "PathError"]


class ConfigError(ValueError):
    """A configuration value is invalid.

    Parameters
    ----------
    message : str
        What is wrong, as a plain sentence.
    source : str, optional
        The file the value came from.
    line : int, optional
        The 1-based line of `source` holding the value.
    """

    def __init__(self, message, source=None, line=None):
        self.source = source
        self.line = line
        where = ""
        if source is not None:
            where = f"{source}, line {line}: " if line is not None else f"{source}: "
        super().__init__(where + message)


class ChainError(ValueError):
    """A machine chain whose bodies do not form a tree, or whose axes do not match its bodies' joints.

    Parameters
    ----------
    message : str
        What is wrong, naming the bodies.
    key : str
        The parameter at fault: ``"parent"`` or ``"axis"`` of a body, or the chain's ``"axes"``.
    body : int, optional
        The body (1..n) whose `key` it is; None for the chain's own parameter.
    """

    def __init__(self, message, key, body=None):
        self.key = key
        self.body = body
        super().__init__(message)


class TraceFormatError(ConfigError):
    """A measured-trace CSV file does not follow the trace format.

    Parameters
    ----------
    message : str
        What is wrong, naming the column.
    source : str, optional
        The CSV file.
    line : int, optional
        The 1-based line of the offending row or header.
    """


class OutputError(OSError):
    """A result file or the output folder cannot be written (permissions, full disk, ...).

    The message names the file and the reason, e.g.
    ``cannot write out/circle.csv: Permission denied``.
    """


class ContoursimWarning(UserWarning):
    """Something the user should know about a result that is still produced.

    E.g. G-code words that were ignored, or a servo axis whose current
    command was clipped at its limit. The command line prints each as one line.
    """


class PathError(ValueError):
    """A reference path is degenerate (zero length, collinear arc points, ...), or one the machine cannot follow.

    Parameters
    ----------
    message : str
        What is wrong.
    primitive : int, optional
        The index of the path's primitive at fault (a G-code program maps it to its block's line).
    axis : str, optional
        The machine axis at fault (one the path would take outside its travel).
    """

    def __init__(self, message, primitive=None, axis=None):
        self.primitive = primitive
        self.axis = axis
        super().__init__(message)


class UnstableLoopError(ValueError):
    """A servo loop is unstable or too poorly damped to simulate.

    Parameters
    ----------
    message : str
        Which axis and why.
    margins : dict
        Gain margin [-], phase margin [deg] and their crossover frequencies
        [rad/s], as computed by :func:`control.stability_margins`.
    """

    def __init__(self, message, margins=None):
        self.margins = margins
        super().__init__(message)
