"""The asset library (PSDR-Room section 4, the object stage): procedural furniture, user
OBJ/PLY/USD models, and their retrieval by silhouette and depth descriptors of multi-view
renders. A library like render/: no stage, no rule; docs/assets.md."""
