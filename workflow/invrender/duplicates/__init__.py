"""Structure from Duplicates: poses and one shared mesh of identical objects in one image."""
