"""invrender: inverse rendering of real spaces by Monte Carlo inverse path tracing."""

__version__ = "0.1.0"
