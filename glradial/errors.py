"""glradial's errors: every error glradial defines is a :class:`Error`, and also the built-in
exception it was before (``except ValueError`` and ``except RuntimeError`` keep working)."""

from __future__ import annotations


class Error(Exception):
    """Base of the errors glradial defines: ``except glradial.Error`` catches all of them."""


class GLUnavailableError(Error, RuntimeError, ValueError):
    """No OpenGL 3.3 context could be created (EGL library or driver missing, or a forked child
    with no fresh EGL display left).

    A ``RuntimeError`` (the environment is at fault) that is also a ``ValueError``, so callers that
    catch bad-input errors at the API boundary catch it too; the message names the library and the
    packages that provide it.
    """


class ShaderCompileError(Error, RuntimeError):
    """A GLSL program failed to compile or link; the message names file and line."""


class ModelLoadError(Error, RuntimeError, ValueError):
    """The model file exists but is not a usable glradial ONNX model (corrupt, wrong graph,
    checksum mismatch). Also a ``ValueError``: a bad model is bad input to the caller."""


class LensTrackError(Error, ValueError):
    """A lens-track sidecar (CSV or JSON) that cannot be read: the message names the file and the
    line of the first bad row. Also a ``ValueError``."""
