"""Training data: perspective crops of panoramas with a lens applied (renderer, crop producer,
datasets) and procedural stadium panoramas with their styles and seed splits."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..lazy import attach

if TYPE_CHECKING:
    from .crop_producer import crop_batches
    from .crops import MAX_SUPERSAMPLE, PAPER_RANGES, CropParams, CropRenderer, crop_labels, lens_covers_frame, load_panorama, render_crop_set, render_crops, sample_crop_params
    from .dataset import write_crops_dataset
    from .stadium import StadiumRenderer, stadium_panorama, stadium_panorama_cached
    from .stadium_style import HALF_LENGTH, HALF_WIDTH, sample_style, split_seeds, stadium_split

__getattr__, __dir__, __all__ = attach(__name__, __file__)
