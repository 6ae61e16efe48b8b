"""Eq. 4 of PSDR-Room: the joint optimisation of materials and lights under global illumination,

    L = L1(R_1/8(theta), I_1/8) + sum_i L1(mu(M_i^r), C_i) + sum_k L1(T_G(R_k(theta)), T_G(I_k)),

the photo and the render at 1/8 of the photo's size, the mean rendered colour over each part's
mask against its median photo colour, and the Gram descriptor of each crop pair.

Lights: for fixed materials, transport is linear in each light's radiance, so one render per
light at unit radiance gives the image as sum_j L_j I_j exactly (up to Monte Carlo noise), and
the radiances minimising the squared image error are a non-negative least-squares solve per
colour channel (scipy's NNLS). The optimisation alternates that exact light solve with Adam
steps on the materials through the adjoint path tracer (render/adjoint.py: dL/d kd map), chained
through the torch material evaluation (model.RoomModel) to each material's texture parameters.
The light solve minimises the squared error, not Eq. 4's L1 (NNLS is the closed form of the
former); the material steps use Eq. 4 as written (L1 terms, the library's Gram loss).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import torch
from scipy.optimize import nnls

from ..materials.base import from_unit, to_unit
from ..materials.gram import gram_loss, gram_matrices
from ..materials.retrieval import default_network
from ..render.adjoint import backward, backward_seed
from ..render.renderer import Renderer, pixel_requests
from .init import damped, pooled_parts, tied_albedo, tied_parts
from .model import PartMaterial, RoomModel

__all__ = ["Eq4Settings", "Views", "solve_lights", "light_renders", "Eq4"]

log = logging.getLogger(__name__)

_EDGE = 1e-3  # parameters start at least this far (in [0, 1] of their bounds) from the bounds


@dataclass
class Eq4Settings:
    rounds: int = 4  # alternations: the light solve, then `steps` material steps
    steps: int = 8
    learning_rate: float = 0.08  # Adam, on the logits of the parameters in their bounds
    spp: int = 8  # per material step (forward and adjoint)
    light_spp: int = 16  # per light render of the light solve
    mean_weight: float = 1.0  # Eq. 4's mean-colour term
    # Eq. 4's crop term: the library's Gram loss (materials/gram.py: each layer in units of its
    # value on white noise of deviation 0.1, the crop's mean removed; about 1 for a texture
    # against a flat crop). Not relative to the target's own (a flat target made that ratio
    # 30 times the rest of Eq. 4 on the test room).
    gram_weight: float = 0.05
    # "grey": one radiance per light, the same in R, G and B (the paper's uniform initial
    # radiance); "rgb": one per channel. A photo's colour is albedo times light: with RGB lights
    # the two trade colour freely wherever no emitter is seen (measured on the test room: a
    # light behind the camera went blue, 14/24/30 for a grey 9, and the walls orange).
    light_colour: str = "grey"
    # After the Adam steps, each plain part's albedo is moved halfway to the value that makes
    # its rendered mean the photo's under the current shading (Eq4.albedo_step), as the light
    # solve is exact for the lights. Without it, Adam's small steps on the albedo
    # and the exact light solve crawl along the albedo-light valley (measured: walls 0.57 -> 0.59
    # in 18 steps for a true 0.70).
    closed_form_albedo: bool = True


class Views:
    """The rays one step renders: the photo's camera at reduced size, then each crop's camera;
    ray ids continue across them so that no two pixels share random numbers."""

    def __init__(self, small, crops):
        self.cameras = [small, *crops]
        requests, offset, self.slices = [], 0, []
        for index, cam in enumerate(self.cameras):
            requests.append(pixel_requests(cam, index, offset))
            self.slices.append(slice(offset, offset + cam.width * cam.height))
            offset += cam.width * cam.height
        self.requests = np.concatenate(requests)

    def images(self, values):
        """Per camera, its (H, W, 3) image from per-ray values (numpy or torch)."""
        return [values[s].reshape(c.height, c.width, 3) for s, c in zip(self.slices, self.cameras)]


def make_renderer(model: RoomModel, materials, radiance, device: str | None = None) -> Renderer:
    """A renderer of the model with the features (render/analysis.py) of its brightest case:
    the bounces are chosen for every part at the plain colour's upper bound, so no albedo the
    optimiser reaches is rendered with too few (a grey 0.5 start gave 5-6 bounces where a true
    0.8 ceiling needs 10: the albedos came out 20 % low)."""
    from ..render.analysis import analyse
    from ..scene.types import Scene

    bright = [PartMaterial("plain", {"colour": torch.full((3,), 0.9)}) for _ in materials]
    probe = Scene(
        mesh=model.scene.mesh,
        maps=model.maps(bright, np.maximum(np.asarray(radiance, float), 1e-3)),
        cameras=model.scene.cameras,
    )
    features = analyse(probe, device=device)
    scene = Scene(mesh=model.scene.mesh, maps=model.maps(materials, radiance), cameras=model.scene.cameras)
    return Renderer(scene, features, device=device)


def light_renders(renderer: Renderer, model: RoomModel, materials, camera, spp: int, seed: int):
    """(K, H, W, 3) renders of each light alone at unit radiance, the materials as they are, and
    the variance of each pixel's mean."""
    requests = pixel_requests(camera)
    means, variances = [], []
    base = model.maps(materials)
    for j in range(len(model.lights)):
        renderer.set_maps(model.with_lights(base, only_light=j))
        mean, var, _ = renderer.render_requests([camera], requests, spp, seed + 7919 * j)
        means.append(mean.reshape(camera.height, camera.width, 3))
        variances.append(var.reshape(camera.height, camera.width, 3))
    shape = (0, camera.height, camera.width, 3)
    return (np.stack(means), np.stack(variances)) if means else (np.zeros(shape), np.zeros(shape))


def solve_lights(
    unit: np.ndarray,
    target: np.ndarray,
    mask: np.ndarray | None = None,
    previous=None,
    colour: str = "rgb",
    variance: np.ndarray | None = None,
) -> np.ndarray:
    """argmin_{L >= 0} || sum_j L_j unit_j - target ||^2 over the masked pixels: (K, 3)
    radiances from (K, H, W, 3) unit renders and an (H, W, 3) target, per channel ("rgb") or one
    grey value per light over all channels ("grey").

    The unit renders are Monte Carlo estimates: E[I_j . I_j] = mu_j . mu_j + sum var_j, so the
    plain normal matrix is too large on its diagonal and the radiances shrink (as the room_lights
    scale, docs/room.md). With ``variance`` that excess is subtracted: NNLS then runs on R x = c
    with R^T R = A^T A - diag(sum var) and R^T c = A^T b (the same quadratic); where the
    corrected matrix is not positive definite (noise as large as the signal) the plain fit is
    kept. A light whose render is black there (nothing it lights is seen) keeps its
    ``previous`` radiance (else 0): the photo says nothing about it."""
    k = len(unit)
    mask = np.ones(target.shape[:2], bool) if mask is None else mask
    out = np.zeros((k, 3)) if previous is None else np.array(previous, np.float64).reshape(k, 3)
    channels = [[0], [1], [2]] if colour == "rgb" else [[0, 1, 2]]
    for c in channels:
        a = unit[:, mask][..., c].reshape(k, -1).T.astype(np.float64)  # (pixels x channels, K)
        b = target[mask][..., c].reshape(-1).astype(np.float64)
        seen = np.linalg.norm(a, axis=0) > 1e-9 * max(1.0, np.linalg.norm(b))
        if not seen.any():
            continue
        a = a[:, seen]
        x = None
        if variance is not None:
            excess = variance[:, mask][..., c].reshape(k, -1)[seen].sum(1).astype(np.float64)
            normal = a.T @ a - np.diag(excess)
            try:
                r = np.linalg.cholesky(normal).T
                x, _ = nnls(r, np.linalg.solve(r.T, a.T @ b))
            except np.linalg.LinAlgError:
                x = None
        if x is None:
            x, _ = nnls(a, b)
        out[np.ix_(np.flatnonzero(seen), c)] = x[:, None]
    return out


@dataclass
class _Crop:
    camera_index: int
    part: int
    target_grams: list


class Eq4:
    """The state of the joint optimisation: the model, the materials (their free texture
    parameters as logits), the lights' radiances, the renderer and the targets."""

    def __init__(
        self,
        model: RoomModel,
        materials: list[PartMaterial],
        radiance: np.ndarray,
        renderer: Renderer,
        views: Views,
        targets: list[np.ndarray],
        part_masks: np.ndarray,
        medians: np.ndarray,
        crop_parts: list[int],
        settings: Eq4Settings,
        seed: int = 0,
        ties: dict[int, list[int]] | None = None,
    ):
        self.model, self.materials, self.renderer, self.views = model, materials, renderer, views
        # Plain parts without pixels in the image term follow the seen parts of their segments
        # (init.tied_parts): not Adam's to move, set with the closed-form albedos.
        if ties is None:
            ties = tied_parts(model.parts, part_masks, [True] * len(model.parts))
        self.ties = {i: t for i, t in ties.items() if materials[i].kind == "plain"}
        self.pools = pooled_parts(model.parts, part_masks)  # plain box surfaces of one segment: one albedo
        self.closed: dict[int, np.ndarray] = {}  # each plain part's last closed-form albedo
        self.radiance = np.asarray(radiance, np.float64).reshape(len(model.lights), 3)
        self.settings, self.seed = settings, seed
        self.targets = [torch.from_numpy(np.asarray(t, np.float32)) for t in targets]
        self.part_masks = part_masks  # (parts, h, w) bool at the small camera: rendered part and photo segment
        self.medians = torch.as_tensor(np.asarray(medians, np.float32))
        self.net = default_network()
        self.crops = []
        for k, part in enumerate(crop_parts):
            target = self.targets[1 + k]
            with torch.no_grad():
                grams = gram_matrices(self.net, target)
            self.crops.append(_Crop(1 + k, part, grams))
        self.logits = []
        for mat in materials:
            m = mat.material
            unit = to_unit(m, m.complete({k: torch.as_tensor(v).detach().clone() for k, v in mat.params.items()}))
            free = {
                p.name: torch.logit(unit[p.name].clamp(_EDGE, 1 - _EDGE)).requires_grad_(True)
                for p in m.params
                if p.texture
            }
            self.logits.append((unit, free))
        params = [z for i, (_, free) in enumerate(self.logits) if i not in self.ties for z in free.values()]
        self.optimizer = torch.optim.Adam(params, lr=settings.learning_rate) if params else None
        self.history: list[dict] = []
        self.step_count = 0

    # --- parameters ---------------------------------------------------------------------
    def current(self, i: int) -> dict:
        unit, free = self.logits[i]
        u = dict(unit)
        u.update({k: torch.sigmoid(z) for k, z in free.items()})
        return from_unit(self.materials[i].material, u)

    def sync(self) -> None:
        """The materials' params from the logits (detached), for baking and writing."""
        for i, mat in enumerate(self.materials):
            with torch.no_grad():
                mat.params = {k: v.detach().clone() for k, v in self.current(i).items()}

    # --- the loss -----------------------------------------------------------------------
    def loss(self, values: torch.Tensor) -> tuple[torch.Tensor, dict]:
        """Eq. 4 of per-ray radiance values (n, 3), and its terms."""
        s = self.settings
        images = self.views.images(values)
        small = images[0]
        image_term = (small - self.targets[0]).abs().mean()
        mean_terms = []
        for i in range(len(self.materials)):
            mask = torch.from_numpy(self.part_masks[i])
            if mask.any():
                mean_terms.append((small[mask].mean(0) - self.medians[i]).abs().mean())
        mean_term = torch.stack(mean_terms).mean() if mean_terms else torch.zeros(())
        gram_terms = [
            gram_loss(self.net, images[c.camera_index].permute(2, 0, 1)[None], c.target_grams)[0] for c in self.crops
        ]
        gram_term = torch.stack(gram_terms).mean() if gram_terms else torch.zeros(())
        total = image_term + s.mean_weight * mean_term + s.gram_weight * gram_term
        terms = {
            name: float(t.detach())
            for name, t in (("image_l1", image_term), ("mean_colour", mean_term), ("gram", gram_term))
        }
        return total, terms

    def render(self, spp: int, seed: int) -> np.ndarray:
        self.sync()
        self.renderer.set_maps(self.model.maps(self.materials, self.radiance))
        mean, _, _ = self.renderer.render_requests(self.views.cameras, self.views.requests, spp, seed)
        return mean

    def evaluate(self, spp: int, seed: int) -> tuple[list[np.ndarray], dict]:
        """The images of every view and the loss's terms, without a step."""
        mean = self.render(spp, seed)
        with torch.no_grad():
            total, terms = self.loss(torch.from_numpy(mean))
        return self.views.images(mean), {"loss": float(total), **terms}

    # --- steps --------------------------------------------------------------------------
    def light_step(self) -> None:
        self.sync()
        small = self.views.cameras[0]
        unit, variance = light_renders(
            self.renderer,
            self.model,
            self.materials,
            small,
            self.settings.light_spp,
            self.seed + 104729 * (self.step_count + 1),
        )
        self.radiance = solve_lights(
            unit, self.targets[0].numpy(), previous=self.radiance, colour=self.settings.light_colour, variance=variance
        )

    def albedo_step(self) -> None:
        """Each plain part's colour toward sum P / sum S over its pixels (over its pool's: the
        seen walls, init.pooled_parts), S the render over the albedo (the shading,
        interreflections at the current albedos): the albedo that makes the part's rendered
        mean the photo's; then each unseen plain part from the parts it follows
        (init.tied_albedo). A ratio of sums, not least squares: S is a Monte Carlo estimate,
        and sum S^2 overestimates its square by the variance (measured: a least-squares 0.69
        for a true 0.80 ceiling at 16 spp), while sum S is unbiased. Nor Eq. 4's L1 minimiser
        (the S-weighted median of P / S, tried): biased on noisy S (the Eq. 4 test's ceiling
        0.73 for 0.80). Halfway there (init.damped: the full step oscillates away from the
        truth where a part lights itself much)."""
        small = self.views.cameras[0]
        mean = self.render(self.settings.light_spp, self.seed + 7 + 104729 * (self.step_count + 1))
        render = mean[self.views.slices[0]].reshape(small.height, small.width, 3).astype(np.float64)
        target = self.targets[0].numpy().astype(np.float64)
        shading = np.zeros_like(render)
        for i, mat in enumerate(self.materials):  # every part's shading: the tied parts read it
            mask = self.part_masks[i]
            kd = self.model.values(i, mat)[0] if mat.kind != "plain" else None
            colour = mat.params["colour"].detach().numpy() if kd is None else np.mean(kd, axis=0)
            shading[mask] = render[mask] / np.maximum(np.asarray(colour, np.float64), 1e-6)
        for i, mat in enumerate(self.materials):
            if mat.kind != "plain" or not self.part_masks[i].any():
                continue
            pool = [j for j in self.pools.get(i, [i]) if self.materials[j].kind == "plain"]
            mask = np.any(self.part_masks[pool], axis=0)
            value = target[mask].sum(0) / np.maximum(shading[mask].sum(0), 1e-12)
            self._set_colour(i, self._damped(i, value))
        for i, tied in self.ties.items():
            value = tied_albedo(self.medians[i].numpy(), target, shading, self.part_masks, tied)
            if value is not None:
                self._set_colour(i, self._damped(i, value))
        self.sync()

    def _damped(self, i: int, value) -> np.ndarray:
        """Halfway (init.damped) from the last closed-form albedo, not from where Adam's
        noise-sized steps left it: half of those would stay (the Eq. 4 test's ceiling stayed
        at 0.76 for 0.80). A secant estimate of the best step (1 / (1 + m)) from the last two
        rounds was tried: on Monte Carlo shading it sent that ceiling to 0.73/0.68/0.62."""
        start = self.closed.get(i, self.materials[i].params["colour"].numpy())
        self.closed[i] = np.clip(damped(start, value), 0.01, 0.89)
        return self.closed[i]

    def _set_colour(self, i: int, value) -> None:
        unit = {"colour": torch.as_tensor(np.clip(value, 0.01, 0.89), dtype=torch.float32)}
        m = self.materials[i].material
        z = torch.logit(to_unit(m, m.complete(unit))["colour"].clamp(_EDGE, 1 - _EDGE))
        with torch.no_grad():
            self.logits[i][1]["colour"].copy_(z)

    def material_step(self) -> dict:
        seed = self.seed + 1000 + self.step_count
        self.step_count += 1
        self.sync()
        # Each procedural part evaluated once, with its graph: the same values go into the maps
        # (through the model's cache) and carry the adjoint's gradient back.
        evaluated = {}
        for i, mat in enumerate(self.materials):
            if self.logits[i][1] and mat.kind != "plain":
                params = self.current(i)
                kd, ks, ka = self.model.evaluate(i, PartMaterial(mat.kind, params, mat.transform, mat.meters_per_unit))
                evaluated[i] = kd
                self.model.prime(i, mat, (kd.detach().numpy(), ks.detach().numpy(), ka.detach().numpy()))
        self.renderer.set_maps(self.model.maps(self.materials, self.radiance))
        mean, _, _ = self.renderer.render_requests(self.views.cameras, self.views.requests, self.settings.spp, seed)
        values = torch.from_numpy(mean).requires_grad_(True)
        total, terms = self.loss(values)
        total.backward()
        adjoint = values.grad.numpy()
        if self.optimizer is not None and np.abs(adjoint).max() > 0:
            grads = backward(
                self.renderer,
                self.views.cameras,
                self.views.requests,
                adjoint,
                self.settings.spp,
                backward_seed(seed),
                maps=("kd",),
            )
            per_part = self.model.gather(grads["kd"])
            self.optimizer.zero_grad()
            chained = 0.0
            for i, mat in enumerate(self.materials):
                if not self.logits[i][1] or i in self.ties:
                    continue
                if i in evaluated:
                    kd = evaluated[i]
                else:  # a plain part: one colour, cheap
                    kd, _, _ = self.model.evaluate(
                        i, PartMaterial(mat.kind, self.current(i), mat.transform, mat.meters_per_unit)
                    )
                chained = chained + (kd * torch.from_numpy(per_part[i].astype(np.float32))).sum()
            if torch.is_tensor(chained):
                chained.backward()
                self.optimizer.step()
        record = {"step": self.step_count, "loss": float(total.detach()), **terms}
        self.history.append(record)
        return record

    def run(self, progress=None) -> list[dict]:
        """`rounds` alternations of the light solve and `steps` material steps, and a final light
        solve for the final materials."""
        started = time.perf_counter()
        for r in range(self.settings.rounds):
            self.light_step()
            record = None
            for _ in range(self.settings.steps):
                record = self.material_step()
            # Last in the round, so that Adam's noisy steps (about the learning rate whatever the
            # gradient) do not leave the plain albedos off their exact value.
            if self.settings.closed_form_albedo:
                self.albedo_step()
            if record is None:
                continue
            log.info(
                "Eq. 4 round %d: loss %.5f (image %.5f, mean colour %.5f, gram %.4f), %.1f s",
                r + 1,
                record["loss"],
                record["image_l1"],
                record["mean_colour"],
                record["gram"],
                time.perf_counter() - started,
            )
        self.light_step()
        self.sync()
        return self.history
