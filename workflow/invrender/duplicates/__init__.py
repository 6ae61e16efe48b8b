"""Structure from Duplicates: poses and one shared mesh from one image of identical objects."""
