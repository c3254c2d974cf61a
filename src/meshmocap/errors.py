"""Every exception and warning meshmocap raises, in one place.

Each error subclasses both :class:`MeshmocapError` (so callers can catch everything the
library raises on purpose) and the matching built-in (so generic ``except ValueError``
code keeps working). Messages are one line: the file or argument, what was expected,
what was found.
"""

from __future__ import annotations


class MeshmocapError(Exception):
    """Base class of every error meshmocap raises on purpose."""


class InputError(MeshmocapError, ValueError):
    """An argument has the wrong shape, dtype, value or option name."""


class ArgumentTypeError(MeshmocapError, TypeError):
    """An argument of a public function is of the wrong type (a number where a path is
    expected); the message names the function, the argument, what was expected and what
    was found."""


class MeshError(MeshmocapError, ValueError):
    """A mesh or template is malformed (NaN vertices, bad faces, non-manifold, ...)."""


class BodyPartError(MeshError):
    """A rig cannot be placed on one part of a template's body (the cage's quads on a
    performer whose first frame is far from a standing pose, or in loose clothing).

    Attributes
    ----------
    part : str
        The part in words (``"left shoulder"``, ``"chest junction"``).
    reason : str
        Why, in a few words, without the part.
    """

    def __init__(self, message: str, *, part: str, reason: str):
        super().__init__(message)
        self.part, self.reason = part, reason


class SkeletonError(MeshmocapError, ValueError):
    """A skeleton is malformed (bad parents, duplicate names, unknown joint)."""


class FormatError(MeshmocapError, ValueError):
    """A file does not follow its format (truncated BVH, channel mismatch, bad AMC, ...)."""


class MeshmocapFileNotFoundError(MeshmocapError, FileNotFoundError):
    """A file or folder the user named does not exist."""


class FolderBusyError(MeshmocapError, BlockingIOError):
    """Another process is writing into the folder (its lock is held)."""


class FitError(MeshmocapError, RuntimeError):
    """A frame (or a fit) could not be fitted: too few observed points, no correspondence,
    singular normal equations, a non-finite result. The tracking driver flags the frame
    ``failed`` and coasts across it.

    A RuntimeError rather than an ArithmeticError: most causes are not arithmetic (an empty
    or tiny observation, no compatible pair); the computation simply has no answer for this
    input at run time, and code catching ``ValueError`` for user mistakes must not catch it.
    """


class MeshmocapWarning(UserWarning):
    """Base class of the warnings meshmocap emits."""


class KernelCacheWarning(MeshmocapWarning):
    """numba cannot cache the compiled kernels: they compile again in every process."""


class GreyMaskWarning(MeshmocapWarning):
    """A silhouette image is not binary (grey levels) and was thresholded."""


class MissingFrameWarning(MeshmocapWarning):
    """A frame was dropped or carved from fewer cameras; the rest of the capture is kept."""


def where(path: object, line: int | None = None) -> str:
    """Return ``"path"`` or ``"path:line"`` for error messages."""
    return f"{path}:{line}" if line is not None else f"{path}"


class OutputPathError(MeshmocapError, OSError):
    """An output path cannot be written: a read-only place, a file standing where a folder
    should be, a folder where a file is expected."""


class ProtectedPathError(MeshmocapError, PermissionError):
    """A command other than ``track`` was asked to write a track folder's own files."""


class CaptureMismatchError(MeshmocapError, ValueError):
    """A track is scored against a capture it was not made from."""
