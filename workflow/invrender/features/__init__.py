"""The `features` stage: which effects a scene calls for, written as features.json
(``stage.run``); the decision itself is render/analysis.py, shared with synthesis and tools."""

from .stage import run

__all__ = ["run"]
