"""Structure from Duplicates: poses of identical objects and their shared mesh from one image."""
