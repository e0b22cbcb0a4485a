"""raingauge: a camera rain gauge built on Garg & Nayar, "Vision and Rain" (IJCV 2007).

Subpackages
-----------
physics     pure functions of rain physics, SI units inside
vision      frame-stack algorithms (detection, dynamics, removal), no I/O
gauge       the camera rain gauge (Sec. 8)
render      the rain simulator, drop appearance and close-up streaks
instrument  the field-instrument loop, sources and history
"""

__version__ = "0.1.0"
