"""MILO-Net's pieces against their definitions: the presets, Eq. 6's encoding, the template's
constraints (section 3.5), the straight-through material choice, the losses' derivatives."""

import math

import numpy as np
import pytest
import torch

from invrender.milo.config import PRESETS, resolve, settings_hash
from invrender.milo.losses import image_loss, value_loss
from invrender.milo.network import EMITTER_KA, Encoding, MiloNet, hard_through
from invrender.render.adjoint import GRAD_CHANNELS
from invrender.scene.types import SceneError


def test_presets_resolve_and_refuse_what_they_do_not_know():
    assert (
        resolve("paper")["layers"] == 16 and resolve("paper")["width"] == 1024 and resolve("paper")["materials"] == 64
    )
    assert resolve("cpu", {"lr_mlp": 1})["lr_mlp"] == 1.0  # an int where a float is wanted
    with pytest.raises(SceneError, match="preset: expected one of paper, cpu, demo"):
        resolve("gpu")
    with pytest.raises(SceneError, match="overrides.iterationz: expected one of the settings"):
        resolve("demo", {"iterationz": 3})
    with pytest.raises(SceneError, match="overrides.iterations: expected a int"):
        resolve("demo", {"iterations": 2.5})
    with pytest.raises(SceneError, match="emitters: expected 0 .. materials - 2"):
        resolve("demo", {"emitters": 7})


def test_settings_hash_follows_what_changes_the_computation():
    demo = PRESETS["demo"]
    assert settings_hash(demo) == settings_hash(dict(demo, checkpoint_every=7))
    assert settings_hash(demo) != settings_hash(dict(demo, iterations=301))


def test_encoding_is_eq6():
    x = torch.tensor([[0.25, -0.5, 0.75]])
    out = Encoding(3)(x)[0].numpy()
    expected = [*x[0].tolist()]
    expected += [math.sin(2**level * math.pi * v) for v in x[0].tolist() for level in range(3)]
    expected += [math.cos(2**level * math.pi * v) for v in x[0].tolist() for level in range(3)]
    np.testing.assert_allclose(out, expected, atol=1e-6)


def test_template_keeps_section_35s_constraints():
    settings = resolve("demo", {"materials": 6, "emitters": 2})
    rows = MiloNet(settings, emission=12.0, sky=0.5).template().detach()
    emitters, window, normal = rows[:2], rows[2], rows[3:]
    for name in ("kd", "ks"):
        assert torch.all(emitters[:, GRAD_CHANNELS[name]] == 0) and torch.all(window[GRAD_CHANNELS[name]] == 0)
    assert torch.allclose(emitters[:, GRAD_CHANNELS["ka"]], torch.tensor(EMITTER_KA))
    np.testing.assert_allclose(emitters[:, GRAD_CHANNELS["ke"]].numpy(), 12.0, rtol=1e-6)
    assert torch.all(normal[:, GRAD_CHANNELS["ke"]] == 0) and torch.all(normal[:, GRAD_CHANNELS["kw"]] == 0)
    assert torch.all((normal >= 0) & (normal <= 1))
    assert 0 < float(window[GRAD_CHANNELS["kw"]]) < 1


def test_hard_choice_renders_one_material_with_the_softmax_gradient():
    logits = torch.tensor([[0.3, 1.2, -0.4]], requires_grad=True)
    weights = torch.tensor([[1.0, 2.0, 5.0]])
    hard = hard_through(torch.softmax(logits, -1))
    assert hard.tolist() == [[0.0, 1.0, 0.0]]
    (hard * weights).sum().backward()
    soft_logits = logits.detach().clone().requires_grad_(True)
    (torch.softmax(soft_logits, -1) * weights).sum().backward()
    np.testing.assert_allclose(logits.grad.numpy(), soft_logits.grad.numpy(), rtol=1e-6)


@pytest.mark.parametrize("kind", ["mse", "relative_mse", "norm"])
def test_image_loss_derivative_matches_finite_differences(kind):
    rng = np.random.default_rng(3)
    radiance, target = rng.uniform(0, 2, (5, 3)), rng.uniform(0, 2, (5, 3))
    _, adjoint = image_loss(radiance, target, kind, 0.2)
    h = 1e-6
    for j, c in [(0, 0), (2, 1), (4, 2)]:
        up, down = radiance.copy(), radiance.copy()
        up[j, c] += h
        down[j, c] -= h
        numeric = (image_loss(up, target, kind, 0.2)[0] - image_loss(down, target, kind, 0.2)[0]) / (2 * h)
        assert adjoint[j, c] == pytest.approx(numeric, rel=1e-5)


def test_value_loss_is_zero_in_range_and_grows_outside():
    inside = torch.tensor([[0.3, 0.3, 0.3, 0.04, 0.04, 0.04, 0.3, 5.0, 5.0, 5.0, 0.5]])
    assert float(value_loss(inside)) == 0.0
    outside = inside.clone()
    outside[0, GRAD_CHANNELS["kd"]] = torch.tensor([1.2, 0.3, 0.3])  # above 1, and kd + ks above 1
    assert float(value_loss(outside)) == pytest.approx(0.2**2 + 0.24**2, rel=1e-5)
