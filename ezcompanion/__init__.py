"""ezcompanion: a MAVLink guidance companion for intercept guidance in multiple engagement zones.

The guidance law (``ezcompanion.guidance``) is pure and shared by every caller: the reference
simulator (``ezcompanion.sim``), the companion service and the Monte-Carlo validation.
"""

__version__ = "0.1.0"
