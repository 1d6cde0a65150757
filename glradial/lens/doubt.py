"""The doubt policy, decided once for every input kind: a lens that says it is doubtful is not
applied (the frame passes through uncorrected) unless the caller asks for it, and a lens that folds
over inside the frame never is.

Who decides *whether* a reading is doubtful differs by source (the trust model for one frame,
:mod:`glradial.estimation.trust`; the shot fit for a video or live shot,
:mod:`glradial.video.shot_fit`); what follows from it is this one function, called by
:func:`glradial.correct` (images and arrays), ``glradial correct --auto`` on an image, the lens track
of a video (:mod:`glradial.video.shot_track`) and the live corrector's lens
(:mod:`glradial.video.live_lens`).
"""

from __future__ import annotations

from ..errors import check_flag

#: The reason that forbids applying a lens even when doubtful lenses are asked for.
FOLD_OVER = "fold_over"


def applies(doubtful: bool, reason: str, apply_doubtful: bool) -> bool:
    """Whether a lens reading is applied to its frames.

    Args:
        doubtful: the reading says it should not be applied as if sure.
        reason: why (``"ok"`` or ``""`` when sure; :data:`FOLD_OVER` is never applied).
        apply_doubtful: the caller's choice to apply doubtful readings anyway.

    Returns:
        True when the lens is applied, False when the frames pass through uncorrected.

    Raises:
        TypeError: ``apply_doubtful`` is not a bool.

    Example:
        >>> from glradial.lens.doubt import applies
        >>> applies(False, "ok", False), applies(True, "uncertain", False), applies(True, "uncertain", True)
        (True, False, True)
        >>> applies(True, "fold_over", True)
        False
    """
    apply_doubtful = check_flag("apply_doubtful", apply_doubtful)
    return not doubtful or (apply_doubtful and reason != FOLD_OVER)
