"""The `bake` stage: recovered maps, the geometry stage's mesh and the capture's cameras, made
into the scene directory every later stage reads (features, render, export, evaluate, edit)."""
