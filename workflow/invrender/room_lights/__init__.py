"""The light stage's library (mode `room`, PSDR-Room section 4.4): the initial area lights from
the room box and camera (lights.py) and the radiance scale from one unit-radiance render."""
