"""Which pixels give rays: the objects' and the support's, never the rest.

An image with an instance mask (the photograph the segmentation ran on): object pixels are those of
registered copies (a copy without a pose is not in the scene, so its pixels would be explained by
the table behind it), support pixels are the mask's background where the primary ray meets the
support. An image without one (a further photograph of the same pile): object pixels are those
whose primary ray meets a copy, support pixels those whose ray meets the support.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..render.batches import pool_batch
from ..render.renderer import Renderer, pixel_requests
from ..scene.types import Camera

SUPPORT_ID = 0  # the support's instance id: the masks' background value


@dataclass
class RayPools:
    """int4 requests (camera, x, y, ray id) of the object and support pixels, and their radiance."""

    object: np.ndarray
    support: np.ndarray
    object_target: np.ndarray  # (n, 3) float32
    support_target: np.ndarray

    def batch(self, rays: int, object_share: float, seed: int, iteration: int):
        """(requests, targets, how many of them are object rays) of one iteration: `object_share`
        of the rays from object pixels, the rest from support pixels (all from objects when there
        is no support)."""
        n_object = rays if len(self.support) == 0 else min(len(self.object), round(object_share * rays))
        sizes = [n_object, rays - n_object]
        rows = pool_batch(
            [np.arange(len(self.object))[:, None], np.arange(len(self.support))[:, None]], sizes, seed, iteration
        )
        split = min(n_object, len(self.object))
        first, second = rows[:split, 0], rows[split:, 0]
        requests = np.concatenate([self.object[first], self.support[second]])
        targets = np.concatenate([self.object_target[first], self.support_target[second]])
        return requests, targets, len(first)


def pixel_pools(
    renderer: Renderer,
    cameras: list[Camera],
    images: list[np.ndarray],
    masks: list,
    registered: set[int],
    support: bool,
) -> RayPools:
    """The pools over all cameras; masks[k] is camera k's instance-id image or None."""
    parts = {"object": [], "support": [], "object_target": [], "support_target": []}
    for k, (camera, image, ids) in enumerate(zip(cameras, images, masks)):
        requests = pixel_requests(camera, k, renderer.ray_offset(camera))
        hit_id = _hit_ids(renderer, cameras, requests)
        if ids is not None:
            labels = ids.reshape(-1).astype(np.int64)
            on_object = np.isin(labels, list(registered))
            on_support = (labels == SUPPORT_ID) & (hit_id == SUPPORT_ID) if support else np.zeros_like(on_object)
        else:
            on_object = np.isin(hit_id, list(registered))
            on_support = (hit_id == SUPPORT_ID) if support else np.zeros_like(on_object)
        pixels = image.reshape(-1, 3).astype(np.float32)
        parts["object"].append(requests[on_object])
        parts["support"].append(requests[on_support])
        parts["object_target"].append(pixels[on_object])
        parts["support_target"].append(pixels[on_support])
    return RayPools(**{name: np.concatenate(values) for name, values in parts.items()})


def _hit_ids(renderer, cameras, requests) -> np.ndarray:
    """The instance id each request's primary ray hits (-1: nothing)."""
    aovs = renderer.aovs(cameras, requests)
    return np.where(aovs["triangle_id"] >= 0, aovs["instance_id"], -1)


def instance_images(renderer, cameras: list[Camera], masks: list) -> list[np.ndarray]:
    """Per camera its instance-id image: its mask, or without one what the scene's own primary
    rays hit (-1: nothing), as ``pixel_pools`` labels its pixels."""
    out = []
    for k, (camera, ids) in enumerate(zip(cameras, masks)):
        if ids is None:
            requests = pixel_requests(camera, k, renderer.ray_offset(camera))
            ids = _hit_ids(renderer, cameras, requests).reshape(camera.height, camera.width)
        out.append(ids)
    return out
