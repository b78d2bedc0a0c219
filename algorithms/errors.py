"""Project exceptions.

Every problem a user can cause (a bad file, a broken mesh, a parameter out of range) raises a
subclass of :class:`Stylize3DError` whose message is written for a novice: what is wrong, where,
and what to do about it. The GUI shows ``str(error)`` in a dialog; the CLI prints it and exits
non-zero. Never raise these with a bare technical message.
"""

from __future__ import annotations


class Stylize3DError(Exception):
    """Base class of every error a user should see as a plain message."""

    #: CLI exit status used for this kind of error.
    exit_code = 1


class MeshReadError(Stylize3DError):
    """A mesh file could not be read (missing, empty, unparsable, unsupported format)."""

    exit_code = 2


class MeshWriteError(Stylize3DError):
    """A mesh file could not be written (the old file, if any, is left intact)."""

    exit_code = 3


class InvalidMeshError(Stylize3DError):
    """The mesh was read but cannot be processed as it is (NaN, bad indices, non-manifold, ...)."""

    exit_code = 4


class ParameterError(Stylize3DError):
    """A parameter value is outside its allowed range."""

    exit_code = 5


class ConnectionFailed(Stylize3DError):
    """A service on the network (a Dask scheduler) could not be reached, or went away."""

    exit_code = 7
