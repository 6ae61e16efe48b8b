"""The scene format: a mesh with UVs, MILO's parameter maps, the kg cube map, and cameras."""

from .types import Camera, Maps, Mesh, Scene, SceneError

__all__ = ["Camera", "Maps", "Mesh", "Scene", "SceneError"]
