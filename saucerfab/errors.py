"""The one error hierarchy of saucerfab.

Every error a user can cause (a bad file, a bad option, a scene that cannot be
built) is a :class:`SaucerfabError`. Its message says what was wrong, with the
offending value, and what to do about it. The CLI prints ``error: <message>``
and exits with :attr:`SaucerfabError.exit_code`; it never shows a traceback for
these. Internal invariants may still use ``assert``; user input never does.
"""

from __future__ import annotations


class SaucerfabError(Exception):
    """Base class of all user-facing errors."""

    #: process exit code the CLI uses for this kind of error
    exit_code: int = 2


class ConfigError(SaucerfabError):
    """A setting, option or scene file is invalid (bad value, contradiction)."""


class InputFileError(SaucerfabError):
    """An input file is missing, unreadable, truncated, too large or of the wrong kind."""


class ImageError(InputFileError):
    """An input image cannot be used (unreadable, decompression bomb, empty mask)."""


class MaskError(ImageError):
    """An image has no usable foreground mask (all foreground, all background, no plain background)."""


class ShapeError(InputFileError):
    """A base-shape heightfield file cannot be used (wrong size, NaN, unreadable)."""


class DesignError(InputFileError):
    """A design folder is missing, incomplete or from an incompatible schema."""


class SceneFileError(InputFileError):
    """A ``scene.json`` (schema ``saucerfab.scene/1``) is unreadable, too large, not JSON or holds a bad value."""


class MeshError(SaucerfabError):
    """A mesh could not be built or is not printable."""

    exit_code = 1


class GeometryError(SaucerfabError):
    """The viewing geometry is impossible (camera inside the cup, saucer hitting the cup...)."""


class ExportError(SaucerfabError):
    """An export format or printer profile cannot be honoured."""


class OutputError(SaucerfabError):
    """An output cannot be written (a full disk, no permission); the message names the path."""


class Interrupted(SaucerfabError):
    """The user pressed Ctrl-C; work up to the last checkpoint is kept."""

    exit_code = 130
