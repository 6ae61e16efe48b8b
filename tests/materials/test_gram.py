"""The Gram loss: fixed (the same network in every process, no download), it ranks a texture
nearer to itself under a shift than to every other library material, and a user's weights file
(of this network or of VGG19) replaces the random weights; anything else is a SceneError."""

import pytest
import torch

from invrender.materials import PRESETS, Transform
from invrender.materials.gram import RandomGramNet, VGG19Features, descriptor, gram_loss, gram_matrices, load_network
from invrender.scene.types import SceneError


def images(transform):
    return torch.stack([p.type.image(64, p.params(), transform) for p in PRESETS]).permute(0, 3, 1, 2)


def test_network_is_fixed_by_its_seed():
    a, b = RandomGramNet(), RandomGramNet()
    assert all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
    assert not torch.equal(RandomGramNet(seed=1).convs[0].weight, a.convs[0].weight)
    assert load_network().layer_norms == pytest.approx(load_network().layer_norms)


def test_a_texture_is_nearest_to_itself_shifted():
    """Every preset at scale 3 against every preset shifted by (0.37, 0.21) material units: the
    diagonal of the distance matrix is its rows' least, by a margin (measured: the nearest
    other material is at least 1.99x farther, for tiles_brick; 4.97 to 192 for the others)."""
    net = load_network()
    with torch.no_grad():
        here = descriptor(net, images(Transform(3.0)))
        shifted = descriptor(net, images(Transform(3.0, 0.0, (0.37, 0.21))))
    distance = torch.cdist(shifted, here) ** 2  # (shifted preset, preset)
    own = distance.diagonal()
    others = distance + torch.diag(torch.full((len(PRESETS),), float("inf")))
    ratio = others.min(dim=1).values / own
    assert torch.all(ratio > 1.5), {p.name: float(r) for p, r in zip(PRESETS, ratio)}


def test_descriptor_distance_is_the_gram_loss():
    net = load_network()
    x, y = images(Transform(2.0))[:2], images(Transform(2.5))[:2]
    with torch.no_grad():
        d = ((descriptor(net, x) - descriptor(net, y)) ** 2).sum(dim=1)
        loss = gram_loss(net, x, gram_matrices(net, y))
    assert torch.allclose(d, loss, rtol=1e-4)


def test_gram_loss_has_gradients_for_the_image():
    net = load_network()
    x = images(Transform(2.0))[4:5].clone().requires_grad_(True)
    target = images(Transform(2.0, 0.0, (0.3, 0.3)))[5:6]
    gram_loss(net, x, target).sum().backward()
    assert float(x.grad.abs().max()) > 0


def test_user_weights_of_this_network_replace_the_random_ones(tmp_path):
    net = RandomGramNet(seed=7)
    path = tmp_path / "mine.pt"
    torch.save(net.state_dict(), path)
    loaded = load_network(path)
    assert isinstance(loaded, RandomGramNet)
    assert torch.equal(loaded.convs[2].weight, net.convs[2].weight)
    x = images(Transform(2.0))[1:2]
    assert not torch.allclose(gram_matrices(loaded, x)[0], gram_matrices(load_network(), x)[0])


def test_user_vgg19_weights_load_by_torchvision_keys(tmp_path):
    """A VGG19 state dict (torchvision's key names; random values here, the real file cannot be
    fetched), classifier keys included, loads into VGG19Features: five pooling layers of 64 to
    512 channels, a zero loss for a crop against itself and a positive one against another."""
    g = torch.Generator().manual_seed(3)
    state = {
        k: torch.randn(v.shape, generator=g) * 0.05
        for k, v in VGG19Features().state_dict().items()
        if k.startswith("features.")
    }
    state["classifier.0.weight"] = torch.zeros(4, 4)
    path = tmp_path / "vgg19.pth"
    torch.save(state, path)
    net = load_network(path)
    assert isinstance(net, VGG19Features)
    assert torch.equal(net.features[2].weight, state["features.2.weight"])
    x = images(Transform(2.0))[:2, :, :32, :32]
    grams = gram_matrices(net, x)
    assert [g.shape[1] for g in grams] == [64, 128, 256, 512, 512]
    with torch.no_grad():
        loss = gram_loss(net, x, gram_matrices(net, x[[0, 0]]))
    assert float(loss[0]) == pytest.approx(0.0, abs=1e-9) and float(loss[1]) > 0


@pytest.mark.parametrize(
    "content, field",
    [
        ({"convs.0.weight": torch.zeros(3)}, "keys"),
        (
            {f"convs.{i}.{k}": v for i, conv in enumerate(RandomGramNet().convs) for k, v in conv.state_dict().items()}
            | {"convs.0.weight": torch.zeros(32, 3, 5, 5)},
            "convs.0.weight",
        ),
        ([1, 2, 3], "weights"),
    ],
)
def test_bad_weights_files_are_scene_errors(tmp_path, content, field):
    path = tmp_path / "w.pt"
    torch.save(content, path)
    with pytest.raises(SceneError) as error:
        load_network(path)
    assert error.value.field == field and error.value.file == str(path)


def test_unreadable_weights_file_is_a_scene_error(tmp_path):
    path = tmp_path / "w.pt"
    path.write_text("not a torch file")
    with pytest.raises(SceneError, match="torch state dict"):
        load_network(path)


def test_a_crop_of_the_smallest_size_has_a_descriptor_like_any_other():
    """room_materials' crops may be 16 pixels on a side, one pixel after four poolings, where a
    reflect padding fails: the edge is repeated there. A 16 x 48 crop of a texture still lies
    nearer to a 64 x 64 image of the same texture than to the other presets'."""
    net = load_network()
    with torch.no_grad():
        full = descriptor(net, images(Transform(3.0)))
        strips = descriptor(net, images(Transform(3.0))[:, :, 20:36, 8:56])
    assert strips.shape == full.shape and torch.isfinite(strips).all()
    nearest = torch.cdist(strips, full).argmin(dim=1)
    assert (nearest == torch.arange(len(PRESETS))).float().mean() >= 0.8, nearest  # measured: 10 of 10
