"""The room mode's material and light stage (PSDR-Room section 4.4; docs/room-materials.md)."""
