"""Neural subdivision (thesis ch. 4) and its classic baselines.

* :mod:`.topology` -- Loop-topology refinement with edge ids, barycentric tracking, half-flaps.
* :mod:`.data` -- training data by semi-random collapses and successive self-parameterization.
* :mod:`.model` -- the half-flap network (modules I, V, E), inference, weights files.
* :mod:`.train` -- training as a Step generator (best validation checkpoint kept).
* :mod:`.baselines` -- Loop and mid-point (libigl), modified butterfly.
* :mod:`.metrics` -- Hausdorff and mean surface distance (METRO style), the Table 4.2 protocol.

PyTorch is imported lazily (only :mod:`.model` and :mod:`.train` need it).
"""
