"""net: training of the distortion estimator (torch), run from a source checkout.

Modules: :mod:`.model` (architecture + config), :mod:`.loss` (the paper's distortion loss),
:mod:`.augment` (broadcast-style photometric augmentation), :mod:`.data` (training/test batches
from the GL crop stream), :mod:`.train` (single process or ``torchrun``/DDP), :mod:`.export`
(ONNX + metadata), :mod:`.evaluate` (``glradial evaluate`` plus ``.pt`` checkpoints).

Training runs from a source checkout (``python -m net.train`` in the repository root, with the
``train`` extra installed); this package is not part of the glradial wheel. It imports glradial
(metrics, crops, stadiums, evaluation); ``glradial`` never imports it, nor torch.
"""
