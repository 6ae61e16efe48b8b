"""The `duplicates-material` stage: one shared material for every copy, the support's and the sky,
from one photograph (or several) of identical objects, through the adjoint path tracer
(Structure from Duplicates sections 3.2-3.3; MILO's material model).

- ``config.py``: the presets (ci, default) and the regularisers' weights, each with why;
- ``support.py``: the support plane estimated from the poses, as a quad with its own atlas;
- ``rays.py``: the masked ray pools (object and support pixels of every image);
- ``material.py``: the texels' reparametrised values and the regularisers;
- ``train.py``: the loop; ``stage.py:run``: what `invrender duplicates-material` calls.
"""
