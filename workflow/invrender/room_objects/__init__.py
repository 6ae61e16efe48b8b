"""The room's objects (PSDR-Room section 4.3): retrieval from the asset library,
coarse poses from the depth's points on their supports, joint refinement by Eq. 3. docs/room-objects.md."""
