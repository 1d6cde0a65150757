"""glradial.net: the trainable distortion estimator (torch).

Modules: :mod:`.model` (architecture + config), :mod:`.loss` (the paper's distortion loss),
:mod:`.augment` (broadcast-style photometric augmentation), :mod:`.data` (training/test batches
from the GL crop stream), :mod:`.train` (single process or ``torchrun``/DDP), :mod:`.export`
(ONNX + metadata), :mod:`.evaluate` (metrics, tables, plots).

Run from the repository as ``python -m net.train`` or installed as ``python -m glradial.net.train``;
modules import each other relatively so both work. ``import glradial`` never imports this package.
"""
