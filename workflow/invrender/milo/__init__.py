"""The `milo` stage: MILO-Net trained on a capture through the adjoint path tracer (MILO sections
3.3-3.5).

- ``config.py``: the presets (paper, cpu, demo) and the checks of a training config;
- ``network.py``: MILO-Net (positional encodings, three MLPs, the material template) and the
  plain-MLP ablation of the paper's Fig. 12;
- ``losses.py``: the regularisers of Eq. 8, 10 and the value loss; the image loss is Eq. 5;
- ``texels.py``: what the network reads, per atlas texel and per sky direction;
- ``importance.py``: the captured images' brightness projected onto the atlas (section 3.5);
- ``checkpoint.py``: checkpoints that resume bit for bit, refused when they do not fit;
- ``train.py``: the loop; ``stage.py:run``: what `invrender milo` calls.
"""
