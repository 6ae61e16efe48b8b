"""The Gram-matrix texture descriptor and loss (Gatys et al. 2016; PSDR-Room section 3, "Texture
descriptors"): Gram matrices of a CNN's features after each pooling layer, flattened and
concatenated; crops of any size give descriptors of one size.

The paper uses VGG19's five pooling layers. Pretrained weights cannot be downloaded here, so the
default network is a fixed, seeded, random-weight VGG-like stack (five blocks of 3x3 convolution,
ReLU and 2x2 average pooling, receptive fields 3 to about 90 pixels): Gram matrices of random
filters at several scales are known to describe textures well enough to synthesise them
(Ustyuzhaninov et al. 2017, "What does it take to generate natural textures?"). A user's weights
file replaces it: a state dict of this network, or of torchvision's VGG19 (keys
features.N.weight/bias), which then runs as in the paper (max pooling, ImageNet normalisation of
sRGB input, the five pooling layers).

Inputs are linear RGB crops (B, 3, H, W) in [0, 1]. The random network removes each crop's mean
colour first: the mean is the loss's other term (Eq. 4's mean colour), and left in, it would
dominate every Gram matrix (a random filter's response to a constant is its weights' sum times
the colour). VGG19 sees the crop as in the paper (sRGB, ImageNet-normalised).
"""

from __future__ import annotations

import pickle
from pathlib import Path

import torch
from torch import nn

from ..scene.types import SceneError

__all__ = ["RandomGramNet", "VGG19Features", "load_network", "gram_matrices", "gram_loss", "descriptor"]

RANDOM_SEED = 1616
RANDOM_CHANNELS = (32, 64, 96, 128, 128)
# torchvision's VGG19 "E" configuration; "M" is a 2x2 max pool.
VGG19_LAYERS = (64, 64, "M", 128, 128, "M", 256, 256, 256, 256, "M", 512, 512, 512, 512, "M", 512, 512, 512, 512, "M")
IMAGENET_MEAN = (0.485, 0.456, 0.406)
IMAGENET_STD = (0.229, 0.224, 0.225)
# The scale of the per-layer normalisation: white noise of this standard deviation (about a
# textured crop's contrast) has a Gram loss of 1 per layer against a constant crop.
_REFERENCE_STD = 0.1
_REFERENCE_SIZE = 64


class RandomGramNet(nn.Module):
    """Five blocks of 3x3 convolution + ReLU + 2x2 average pooling; weights drawn from a fixed
    seed (He normal: zero-mean, variance 2 / fan-in, so activations keep their scale through
    the ReLUs), biases zero. Average pooling, as Gatys et al. advise for synthesis: max pooling
    of random features favours outliers."""

    def __init__(self, seed: int = RANDOM_SEED, channels=RANDOM_CHANNELS):
        super().__init__()
        g = torch.Generator().manual_seed(seed)
        convs, c_in = [], 3
        for c_out in channels:
            conv = nn.Conv2d(c_in, c_out, 3, padding=1, padding_mode="reflect")
            with torch.no_grad():
                conv.weight.copy_(torch.randn(conv.weight.shape, generator=g) * (2.0 / (c_in * 9)) ** 0.5)
                conv.bias.zero_()
            convs.append(conv)
            c_in = c_out
        self.convs = nn.ModuleList(convs)
        self.requires_grad_(False)

    def prepare(self, x: torch.Tensor) -> torch.Tensor:
        return x - x.mean(dim=(2, 3), keepdim=True)

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """The feature maps after each pooling layer."""
        out = []
        x = self.prepare(x)
        for conv in self.convs:
            x = nn.functional.avg_pool2d(torch.relu(_convolve(conv, x)), 2, ceil_mode=True)
            out.append(x)
        return out


def _convolve(conv: nn.Conv2d, x: torch.Tensor) -> torch.Tensor:
    """``conv`` with its reflect padding, or with the edge repeated where a side is one pixel: a
    crop of 16 pixels is one pixel high after four poolings, and a reflection needs two."""
    if min(x.shape[-2:]) >= 2:
        return conv(x)
    return nn.functional.conv2d(nn.functional.pad(x, (1, 1, 1, 1), mode="replicate"), conv.weight, conv.bias)


class VGG19Features(nn.Module):
    """torchvision's vgg19().features, built here (torchvision does not install beside the CPU
    torch), so a VGG19 state dict loads by the same keys; outputs after each of its five pools."""

    def __init__(self):
        super().__init__()
        layers, c_in = [], 3
        for item in VGG19_LAYERS:
            if item == "M":
                layers.append(nn.MaxPool2d(2, ceil_mode=True))
            else:
                layers += [nn.Conv2d(c_in, item, 3, padding=1), nn.ReLU()]
                c_in = item
        self.features = nn.Sequential(*layers)
        self.register_buffer("mean", torch.tensor(IMAGENET_MEAN).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(IMAGENET_STD).view(1, 3, 1, 1))
        self.requires_grad_(False)

    def prepare(self, x: torch.Tensor) -> torch.Tensor:
        # VGG was trained on sRGB photographs normalised by ImageNet's statistics.
        srgb = torch.where(x <= 0.0031308, 12.92 * x, 1.055 * torch.clamp(x, min=0.0031308) ** (1 / 2.4) - 0.055)
        return (srgb - self.mean) / self.std

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        out = []
        x = self.prepare(x)
        for layer in self.features:
            x = layer(x)
            if isinstance(layer, nn.MaxPool2d):
                out.append(x)
        return out


def load_network(weights=None) -> nn.Module:
    """The default random network, or one from a user's weights file (a state dict of
    RandomGramNet or of torchvision's VGG19, or a whole torchvision VGG19's state dict, whose
    classifier keys are ignored). A file that is neither is a SceneError."""
    if weights is None:
        return _normalised(RandomGramNet())
    path = Path(weights)
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except (OSError, RuntimeError, EOFError, ValueError, pickle.UnpicklingError) as error:
        raise SceneError(path, "weights", f"a torch state dict readable by torch.load ({error})") from None
    if not isinstance(state, dict):
        raise SceneError(path, "weights", "a state dict (a dict of tensors)")
    for net in (RandomGramNet(), VGG19Features()):
        own = net.state_dict()
        keys = [k for k in own if k not in ("mean", "std")]
        if all(k in state for k in keys):
            wrong = [k for k in keys if tuple(state[k].shape) != tuple(own[k].shape)]
            if wrong:
                raise SceneError(
                    path, wrong[0], f"shape {tuple(own[wrong[0]].shape)}, got {tuple(state[wrong[0]].shape)}"
                )
            net.load_state_dict({k: state[k] for k in keys}, strict=False)
            return _normalised(net)
    raise SceneError(
        path,
        "keys",
        "the state dict of invrender's random Gram network (convs.N.weight) "
        "or of torchvision's VGG19 (features.N.weight)",
    )


def _normalised(net: nn.Module) -> nn.Module:
    """Attach per-layer normalisers: the squared Frobenius norm of each layer's Gram matrix on
    fixed white noise, so every layer weighs alike in the loss whatever its width and the
    network's weights."""
    g = torch.Generator().manual_seed(RANDOM_SEED + 1)
    noise = 0.5 + _REFERENCE_STD * torch.randn((1, 3, _REFERENCE_SIZE, _REFERENCE_SIZE), generator=g)
    with torch.no_grad():
        net.layer_norms = [float((gram**2).sum()) for gram in gram_matrices(net, noise)]
    return net


def gram_matrices(net: nn.Module, images: torch.Tensor) -> list[torch.Tensor]:
    """Per layer, the (B, C, C) Gram matrices F F^T / (H W) of the features of images
    (B, 3, H, W) or one image (H, W, 3)."""
    if images.dim() == 3:
        images = images.permute(2, 0, 1)[None]
    grams = []
    for f in net(images):
        b, c, h, w = f.shape
        flat = f.reshape(b, c, h * w)
        grams.append(flat @ flat.transpose(1, 2) / (h * w))
    return grams


def descriptor(net: nn.Module, images: torch.Tensor) -> torch.Tensor:
    """The flattened, concatenated Gram matrices (B, D), each layer scaled by its normaliser
    so that the squared Euclidean distance between two descriptors is `gram_loss`."""
    grams = gram_matrices(net, images)
    return torch.cat([g.flatten(1) / norm**0.5 for g, norm in zip(grams, net.layer_norms)], dim=1)


def gram_loss(net: nn.Module, images: torch.Tensor, target: torch.Tensor | list[torch.Tensor]) -> torch.Tensor:
    """Sum over layers of ||G(image) - G(target)||_F^2 / normaliser, per image (B,); `target` is an
    image or its precomputed `gram_matrices` (fixed targets need them once)."""
    target_grams = gram_matrices(net, target) if torch.is_tensor(target) else target
    total = 0.0
    for g, t, norm in zip(gram_matrices(net, images), target_grams, net.layer_norms):
        total = total + ((g - t) ** 2).sum(dim=(1, 2)) / norm
    return total
