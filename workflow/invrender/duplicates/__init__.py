"""Structure from Duplicates: one image of N identical objects -> per-instance crops,
rotation-aware matches between them, COLMAP virtual cameras -> object poses, and one shared
mesh (Meng et al., "Structure from Duplicates", section 3.1; docs/duplicates.md)."""
