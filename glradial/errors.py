"""glradial's errors: every error glradial defines is a :class:`Error`, and also the built-in
exception it was before (``except ValueError`` and ``except RuntimeError`` keep working); and
:func:`check_count` and :func:`check_flag`, the one checks of the counts and switches glradial takes."""

from __future__ import annotations

import numbers

import numpy as np


class Error(Exception):
    """Base of the errors glradial defines: ``except glradial.Error`` catches all of them.

    Args:
        *args: the message (one string), as for any ``Exception``.

    Raises:
        Nothing itself; glradial raises its subclasses.

    Example:
        >>> import glradial
        >>> issubclass(glradial.LensTrackError, glradial.Error), issubclass(glradial.Error, ValueError)
        (True, False)
    """


class GLUnavailableError(Error, RuntimeError, ValueError):
    """No OpenGL 3.3 context could be created (EGL library or driver missing, or a forked child
    with no fresh EGL display left).

    A ``RuntimeError`` (the environment is at fault) that is also a ``ValueError``, so callers that
    catch bad-input errors at the API boundary catch it too; the message names the library and the
    packages that provide it.

    Args:
        *args: the message (one string).

    Raises:
        Nothing itself; raised by the first call that needs a GL context.

    Example:
        >>> import glradial
        >>> err = glradial.GLUnavailableError("libEGL.so.1 not found (apt-get install libegl1)")
        >>> isinstance(err, RuntimeError) and isinstance(err, ValueError)
        True
    """


class ShaderCompileError(Error, RuntimeError):
    """A GLSL program failed to compile or link; the message names file and line.

    Args:
        *args: the message (one string: the program's files and the driver's log, explained).

    Raises:
        Nothing itself; raised by :mod:`glradial.gl.shaderlib` when a program is built.

    Example:
        >>> import glradial
        >>> try:
        ...     raise glradial.ShaderCompileError("remap.frag:12: undeclared identifier")
        ... except RuntimeError as err:
        ...     print(type(err).__name__, err)
        ShaderCompileError remap.frag:12: undeclared identifier
    """


class ModelLoadError(Error, RuntimeError, ValueError):
    """The model file exists but is not a usable glradial ONNX model (corrupt, wrong graph,
    checksum mismatch). Also a ``ValueError``: a bad model is bad input to the caller.

    Args:
        *args: the message (one string, naming the file and what is wrong with it).

    Raises:
        Nothing itself; raised by :class:`glradial.Estimator` when it loads a model.

    Example:
        >>> import glradial, tempfile, pathlib
        >>> bad = pathlib.Path(tempfile.mkdtemp()) / "broken.onnx"
        >>> _ = bad.write_bytes(b"not an ONNX graph")
        >>> try:
        ...     glradial.Estimator(bad)
        ... except glradial.ModelLoadError:
        ...     print("refused")
        refused
    """


class LensTrackError(Error, ValueError):
    """A lens-track sidecar (CSV or JSON) that cannot be read: the message names the file and the
    line of the first bad row. Also a ``ValueError``.

    Args:
        *args: the message (one string, naming the file and the first bad row).

    Raises:
        Nothing itself; raised where a lens track is read (:mod:`glradial.video.lens_track`).

    Example:
        >>> import glradial
        >>> issubclass(glradial.LensTrackError, ValueError)
        True
    """


def check_count(name: str, value: object, *, minimum: int = 1, unit: str = "", optional: bool = False) -> int | None:
    """``value`` as an ``int`` when it is an integer (Python or NumPy, not a bool) ``>= minimum``
    (``None`` passes where ``optional``), else ``ValueError`` naming ``name``, the rule and the value:
    the one check of every count, stride and thread number glradial takes.

    Args:
        name: the argument's name, as the caller spells it.
        value: what was passed.
        minimum: the smallest value allowed (1: "a positive integer", 0: "a non-negative integer").
        unit: what the count counts (e.g. "frames"), said in the message.
        optional: whether ``None`` is allowed (and returned).

    Returns:
        ``int(value)``, or ``None`` for an allowed ``None``.

    Raises:
        ValueError: ``value`` is not an integer ``>= minimum`` (nor an allowed ``None``).

    Example:
        >>> check_count("every", 3)
        3
        >>> check_count("every", 0, unit="frames")
        Traceback (most recent call last):
        ...
        ValueError: every must be a positive integer (frames), got 0
    """
    if optional and value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < minimum:
        rule = {1: "a positive integer", 0: "a non-negative integer"}.get(minimum, f"an integer >= {minimum}")
        raise ValueError(f"{name} must be {rule}{f' ({unit})' if unit else ''}{' or None' if optional else ''}, got {value!r}")
    return int(value)


def check_flag(name: str, value: object) -> bool:
    """``value`` as a ``bool`` when it is one (Python's or NumPy's), else ``TypeError`` naming ``name``
    and the value: the one check of every on/off argument glradial takes (``1`` or ``"yes"`` is not one).

    Args:
        name: the argument's name, as the caller spells it.
        value: what was passed.

    Returns:
        ``bool(value)``.

    Raises:
        TypeError: ``value`` is not a bool.

    Example:
        >>> check_flag("sparse", True)
        True
        >>> check_flag("sparse", 1)
        Traceback (most recent call last):
        ...
        TypeError: sparse must be a bool, got 1
    """
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {value!r}")
    return bool(value)
